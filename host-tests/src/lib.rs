//! Support for the host tests: the f64 reference model of the detector, which the tests
//! hold the fixed-point core to.

pub mod reference;
