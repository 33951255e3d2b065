//! The fingertip's CAN protocol (work in progress).
