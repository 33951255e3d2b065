#![doc = include_str!("../README.md")]
#![cfg_attr(not(test), no_std)]
#![warn(missing_docs)]

pub mod boot;
pub mod calib;
pub mod can_timing;
pub mod channel_set;
pub mod checksum;
pub mod crash;
pub mod engine;
pub mod flash_map;
pub mod flash_sim;
pub mod load;
pub mod node_id;
pub mod nvm;
pub mod rail;
pub mod recorder;
pub mod reset;
pub mod sampling;
pub mod service_end;
pub mod shared;
pub mod stuck;
pub mod supervise;
pub mod timing;
pub mod tmp117;
pub mod trigger;
pub mod txqueue;
pub mod version;
pub mod wiring;
