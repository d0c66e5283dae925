//! Fields: `fit` and its inputs, the RF walkthrough and what its users hit, the neural
//! shader (MLP), time-varying fields and renders of the fitted field.

mod field_renders;
mod fit;
mod fit_inputs;
mod mlp;
mod rf_usability;
mod rf_walkthrough;
mod time_fields;
