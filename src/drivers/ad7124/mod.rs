//! AD7124-4 driver (in progress).

/// ERROR register content.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ErrorFlags(pub u32);
