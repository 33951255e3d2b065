//! `fingertip`: simulate, replay, evaluate and plot detector runs on the PC.
fn main() {}
