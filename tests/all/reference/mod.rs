//! The CPU reference renderer (`verisplat::cpu`) on its own: closed-form values of its
//! rules, and gsplat's rules on the CPU.

mod closed_forms;
mod gsplat_rules;
