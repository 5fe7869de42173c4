//! What the documents promise, checked: README.md's command blocks run as written and every
//! file README.md and docs/ name exists (`readme`); the bad inputs of docs/field-guarantees.md
//! meet a one-line error within a bounded memory (`bad_inputs`).

#[path = "../common/mod.rs"]
mod common;

mod bad_inputs;
mod readme;
