//! Fingertip firmware.
#![no_std]
