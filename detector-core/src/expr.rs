//! Compiled items written as Rust: [`Rust`] shows a stage, CDF, ramp or decision level as
//! the expression that rebuilds it, through a `const fn` that checks it, in the scope of
//! `detector_core::__private` (what generated code imports).

/// A compiled item shown as the Rust expression that rebuilds it.
pub struct Rust<'a, T>(pub &'a T);
