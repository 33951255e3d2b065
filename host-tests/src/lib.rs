//! The PC side of the fingertip detector.
