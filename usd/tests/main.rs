//! Integration tests of the USD crate (one binary; modules per area).

mod bindings;
mod curves;
mod fuzz;
mod stage;
mod subdiv;
mod traversal;
