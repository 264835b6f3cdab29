//! The board's time base: a free-running 32-bit hardware counter at 1 MHz (TIM2 on the
//! front-end), extended to 64 bits here. The counter keeps counting while the core waits — a
//! flash erase stalls every instruction fetch, not the timer — so a time stamp taken after a
//! stall is true, and the gap the stall left in the DRDY times is visible to the sequencer.
//! Where the DRDY pin is a timer input-capture channel the timer also latches the count at the
//! DRDY edge itself ([`drdy_edge_time`]), so the stamp is the conversion's, not the handler's.

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

/// Where a DRDY time stamp came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StampSource {
    /// The timer latched its count at the DRDY edge (input capture): the conversion's time.
    Captured,
    /// No capture was pending: the count the DRDY handler read when it ran, later than the edge
    /// by the interrupt latency (and by whatever kept the handler from running).
    HandlerRead,
}

/// The time of a DRDY falling edge, in µs on the extended time base.
///
/// `count_now` is the 32-bit counter read in the handler *after* the capture register, and
/// `now_us` its extension ([`Extended64::extend`]); `captured` is the capture register when its
/// capture flag was set, else None. A capture is at most one wrap (71.6 min) older than the
/// read that follows it, so its age is `count_now − captured` modulo 2³², and the edge's
/// 64-bit time is `now_us` minus that age, right across a wrap of the 32-bit counter between
/// the edge and the handler. Without a capture the handler's own read is the stamp, and
/// [`StampSource::HandlerRead`] says so.
pub fn drdy_edge_time(now_us: u64, count_now: u32, captured: Option<u32>) -> (u64, StampSource) {
    match captured {
        Some(capture) => {
            let age = u64::from(count_now.wrapping_sub(capture));
            // An age beyond the time since the counter started cannot come from the order of
            // reads above; saturate rather than wrap to the far future.
            (now_us.saturating_sub(age), StampSource::Captured)
        }
        None => (now_us, StampSource::HandlerRead),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_captured_edge_is_stamped_with_the_capture_not_the_handler_read() {
        let mut t = Extended64::new();
        // The edge at count 1_000, the handler 37 µs later.
        let now = t.extend(1_037);
        assert_eq!(
            drdy_edge_time(now, 1_037, Some(1_000)),
            (1_000, StampSource::Captured)
        );
        // No capture pending: the handler's read, announced as such.
        assert_eq!(
            drdy_edge_time(now, 1_037, None),
            (1_037, StampSource::HandlerRead)
        );
        // Captured in the same microsecond as the read.
        assert_eq!(drdy_edge_time(now, 1_037, Some(1_037)).0, 1_037);
    }

    #[test]
    fn an_edge_before_a_wrap_of_the_counter_and_a_handler_after_it_keep_the_edge_s_time() {
        let mut t = Extended64::new();
        assert_eq!(t.extend(u32::MAX - 100), u64::from(u32::MAX) - 100);
        // The edge 10 µs before the 32-bit counter wraps (count 2³² − 10), the handler at count
        // 19 after the wrap (a 29 µs latency): the stamp lies before the wrap.
        let edge = u32::MAX - 9;
        let now = t.extend(19);
        assert_eq!(now, (1u64 << 32) + 19);
        let (stamp, source) = drdy_edge_time(now, 19, Some(edge));
        assert_eq!(source, StampSource::Captured);
        assert_eq!(stamp, u64::from(u32::MAX) - 9);
        assert_eq!(now - stamp, 29);
        // The same across the second wrap.
        t.extend(u32::MAX);
        let now = t.extend(4);
        assert_eq!(now, (2u64 << 32) + 4);
        assert_eq!(
            drdy_edge_time(now, 4, Some(u32::MAX - 5)).0,
            (1u64 << 32) + u64::from(u32::MAX) - 5
        );
    }

    #[test]
    fn a_capture_from_a_stall_seconds_before_the_handler_is_stamped_at_the_edge() {
        // A flash erase stalls the core 2 s: the edge is latched by the timer, the handler
        // reads 2 s later. The stamp is the edge's, 2 s before the handler's read.
        let mut t = Extended64::new();
        t.extend(5_000_000);
        let now = t.extend(7_000_123);
        assert_eq!(
            drdy_edge_time(now, 7_000_123, Some(5_000_123)),
            (5_000_123, StampSource::Captured)
        );
    }

    #[test]
    fn a_capture_that_would_lie_before_the_start_saturates_at_zero() {
        // Only a capture read after the count could give this; it must not wrap to 2⁶⁴.
        let mut t = Extended64::new();
        let now = t.extend(10);
        assert_eq!(drdy_edge_time(now, 10, Some(20)).0, 0);
    }

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
