//! MPC tick benchmark (placeholder, replaced below).
fn main() {}
