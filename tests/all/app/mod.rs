//! The `verisplat` binary as a user runs it: commands and their errors, the viewer (over
//! its WebSocket and in a browser), `doctor`, `compare` and `eval`, image sequences,
//! shards, videos through ffmpeg, the docs' examples, the help texts, the `tools/`
//! scripts, the former name, and the repository's layout rules.

mod cli;
mod cli_usability;
mod compare;
mod doc_examples;
mod doctor;
mod former_name;
mod help_texts;
mod layout_rules;
mod sequences;
mod shards;
mod tools;
mod transform_flags;
mod video;
mod view;
mod view_browser;
