//! The fingertip's CAN node id, found at boot so that one firmware image serves every
//! finger.
//!
//! Two sources, in this order:
//!
//! 1. **the flash key-value store** (its `node_id` key, [`crate::nvm::Nvm::node_id`]),
//!    passed to [`resolve`];
//! 2. **the strap pins**: four inputs with pull-ups (see the wiring table), bit `i` the
//!    level of strap `i`; a strap tied to ground reads 0. The node id is the 4-bit value
//!    read, so node *n* grounds the straps whose bits are 0 in *n*: node 14 grounds strap
//!    0 only, node 0 all four. All four open (15) means *not strapped*.
//!
//! The STM32G4's option bytes have no user data field, so they cannot carry it. A board
//! with no node id from either source stays off the bus (it cannot pick one without risking
//! another finger's) and says why on its debug log.

use core::fmt;

use fingertip_can::{NodeId, NodeIdSource};

/// The strap pins, and the value they read when none is tied to ground.
pub const STRAPS: usize = 4;
/// Four open straps: the board was not strapped.
pub const UNSTRAPPED: u8 = (1 << STRAPS) - 1;

/// No node id could be found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum NodeIdError {
    /// The store holds a value that is not a node id (0..=14).
    Store(u8),
    /// Neither the store nor the straps give one (all four straps open).
    NotSet,
}

impl fmt::Display for NodeIdError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NodeIdError::Store(v) => write!(f, "the stored node id {v} is not within 0..=14"),
            NodeIdError::NotSet => write!(
                f,
                "no node id: no stored one, and no strap pin is tied to ground"
            ),
        }
    }
}

/// The node id from the store's value (`stored`, if any) or else the strap pins' levels
/// (`straps`, bit `i` strap `i`, high = open), and where it came from.
pub fn resolve(stored: Option<u8>, straps: u8) -> Result<(NodeId, NodeIdSource), NodeIdError> {
    if let Some(v) = stored {
        return NodeId::new(v)
            .map(|n| (n, NodeIdSource::Store))
            .ok_or(NodeIdError::Store(v));
    }
    match straps & UNSTRAPPED {
        UNSTRAPPED => Err(NodeIdError::NotSet),
        v => NodeId::new(v)
            .map(|n| (n, NodeIdSource::Straps))
            .ok_or(NodeIdError::NotSet),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straps_give_every_node_id_and_open_means_unset() {
        for n in 0..=NodeId::MAX {
            assert_eq!(
                resolve(None, n),
                Ok((NodeId::new(n).unwrap(), NodeIdSource::Straps))
            );
        }
        assert_eq!(resolve(None, UNSTRAPPED), Err(NodeIdError::NotSet));
        // Pins above the four are not straps.
        assert_eq!(resolve(None, 0xF3).map(|r| r.0.get()), Ok(3));
    }

    #[test]
    fn the_store_comes_first_and_is_checked() {
        assert_eq!(
            resolve(Some(9), 2),
            Ok((NodeId::new(9).unwrap(), NodeIdSource::Store))
        );
        assert_eq!(resolve(Some(7), UNSTRAPPED).map(|r| r.0.get()), Ok(7));
        assert_eq!(resolve(Some(15), 2), Err(NodeIdError::Store(15)));
        assert!(NodeIdError::NotSet.to_string().contains("strap"));
    }
}
