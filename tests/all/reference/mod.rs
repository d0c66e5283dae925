//! The CPU reference renderer (`verisplat::cpu`) on its own: closed-form values of its
//! rules, gsplat's rules on the CPU, and lenses other than the pinhole.

mod closed_forms;
mod gsplat_rules;
mod lens_resample;
mod lenses;
