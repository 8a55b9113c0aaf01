//! The command line's per-command drivers (the binary's side; `main.rs`
//! parses and dispatches).

pub mod fit;
