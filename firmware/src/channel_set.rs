//! [`ChannelSet`]: a set of channels as a bitset, bit `i` for channel `i`.
//!
//! The firmware names channels two ways: by their place in the ADC scan
//! ([`crate::wiring::ADC_CHANNELS`], e.g. the channels stuck at a rail) and by their place
//! in the detector configuration (the channels a CAN frame feeds, the faulty inputs of a
//! tick). Each set says which in its documentation; the core's [`ChannelMask`] is the
//! same bits for configuration channels, converted at the call into the core.

use detector_core::ChannelMask;

/// A set of channel indices in `0..32`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ChannelSet(u32);

impl ChannelSet {
    /// No channel.
    pub const EMPTY: ChannelSet = ChannelSet(0);

    /// The set whose bit `i` is channel `i`.
    pub const fn from_bits(bits: u32) -> ChannelSet {
        ChannelSet(bits)
    }

    /// Bit `i` for channel `i`.
    pub const fn bits(self) -> u32 {
        self.0
    }

    /// Adds channel `index`; an index of 32 or more is not a channel and adds nothing.
    #[inline]
    pub fn insert(&mut self, index: usize) {
        if let Some(bit) = u32::try_from(index).ok().and_then(|i| 1u32.checked_shl(i)) {
            self.0 |= bit;
        }
    }

    /// Whether channel `index` is in the set.
    #[inline]
    pub const fn contains(self, index: usize) -> bool {
        index < 32 && self.0 & (1 << index) != 0
    }

    /// Whether the set is empty.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }
}

impl FromIterator<usize> for ChannelSet {
    fn from_iter<I: IntoIterator<Item = usize>>(iter: I) -> ChannelSet {
        let mut set = ChannelSet::EMPTY;
        for i in iter {
            set.insert(i);
        }
        set
    }
}

/// Configuration channels, as the core takes them.
impl From<ChannelSet> for ChannelMask {
    fn from(set: ChannelSet) -> ChannelMask {
        set.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn channels_go_in_and_out_of_range_ones_do_not() {
        let mut s = ChannelSet::EMPTY;
        assert!(s.is_empty());
        s.insert(0);
        s.insert(31);
        s.insert(32);
        s.insert(usize::MAX);
        assert_eq!(s.bits(), 0x8000_0001);
        assert!(s.contains(0) && s.contains(31));
        assert!(!s.contains(1) && !s.contains(32));
        assert_eq!([2, 5].into_iter().collect::<ChannelSet>().bits(), 0b10_0100);
        assert_eq!(ChannelMask::from(ChannelSet::from_bits(6)), 6);
    }
}
