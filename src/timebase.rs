//! The board's time base: a free-running 32-bit hardware counter at 1 MHz (TIM2 on the
//! front-end), extended to 64 bits here. The counter keeps counting while the core waits — a
//! flash erase stalls every instruction fetch, not the timer — so a time stamp taken after a
//! stall is true, and the gap the stall left in the DRDY times is visible to the sequencer.

/// A wrapping 32-bit microsecond counter extended to 64 bits. Correct as long as it is read at
/// least once per wrap (2³² µs ≈ 71.6 min); the firmware reads it every supervisor tick (20 ms).
#[derive(Debug, Clone, Copy, Default)]
pub struct Extended64 {
    high: u32,
    last: u32,
}

impl Extended64 {
    /// Starts at zero.
    pub const fn new() -> Self {
        Extended64 { high: 0, last: 0 }
    }

    /// The 64-bit time for the counter value `count` read now.
    pub fn extend(&mut self, count: u32) -> u64 {
        if count < self.last {
            self.high = self.high.wrapping_add(1);
        }
        self.last = count;
        (u64::from(self.high) << 32) | u64::from(count)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_extended_time_runs_on_across_wraps_of_the_32_bit_counter() {
        let mut t = Extended64::new();
        assert_eq!(t.extend(5), 5);
        assert_eq!(t.extend(u32::MAX - 1), u64::from(u32::MAX) - 1);
        // Wrapped between two reads.
        assert_eq!(t.extend(3), (1u64 << 32) + 3);
        assert_eq!(
            t.extend(3),
            (1u64 << 32) + 3,
            "the same count reads the same time"
        );
        assert_eq!(t.extend(10), (1u64 << 32) + 10);
        assert_eq!(t.extend(2), (2u64 << 32) + 2);
    }
}
