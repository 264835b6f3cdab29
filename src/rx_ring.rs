//! The reading side of a circular DMA receive buffer: the front-end's UART receiver.
//!
//! The DMA stream copies every received byte from the USART's data register into an `N`-byte
//! buffer, round and round (RM0090 §10.3.9 "Circular mode"), and its DMA_SxNDTR counts the
//! transfers left in the current round: N after the stream is enabled, down to 1, then reloaded
//! with N after the last transfer of a round (§10.5.6). So the DMA's write position is
//! `N − NDTR`, and the reader only has to remember how far it has read. Nothing here touches
//! registers: the firmware passes in the NDTR it read and a read of one buffer slot, and the
//! host tests drive the same code with a model of the stream.
//!
//! The reader must come back before the DMA has written N more bytes: a full round unread
//! looks exactly like nothing received (write position = read position), and those bytes are
//! lost. The firmware sizes N for that (docs/drivers.md, "UART reception").
//!
//! A stream the hardware stopped (a transfer error clears its EN bit, RM0090 §10.3.18 "Error
//! management") keeps its NDTR, so the bytes it wrote before stopping are still read; the
//! firmware then re-arms it with NDTR = N, which writes from slot 0 again, and calls
//! [`RxRing::restart`] so the reader follows it there.

/// Read position in a circular DMA buffer of `N` bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RxRing<const N: usize> {
    tail: usize,
}

impl<const N: usize> RxRing<N> {
    /// A reader at the start of the buffer, where a freshly enabled stream writes first.
    pub const fn new() -> Self {
        Self { tail: 0 }
    }

    /// Where the DMA writes next, from its NDTR: `N − NDTR`. A transient 0 (after the last
    /// transfer of a round, before the reload) and any value outside 1..=N read as position 0.
    pub const fn head(ndtr: u32) -> usize {
        let ndtr = ndtr as usize;
        if ndtr == 0 || ndtr > N {
            0
        } else {
            N - ndtr
        }
    }

    /// The next received byte, or None when the reader has caught up with the DMA. `ndtr` is the
    /// stream's NDTR read now; `read(i)` reads buffer slot `i` (volatile on the board: the DMA
    /// writes it behind the compiler's back).
    pub fn next(&mut self, ndtr: u32, read: impl FnOnce(usize) -> u8) -> Option<u8> {
        if Self::head(ndtr) == self.tail {
            return None;
        }
        let byte = read(self.tail);
        self.tail = if self.tail + 1 >= N { 0 } else { self.tail + 1 };
        Some(byte)
    }

    /// The stream was re-armed from the start of the buffer (NDTR reloaded with N): read from
    /// slot 0. Call it after the bytes written before the stop have been read.
    pub fn restart(&mut self) {
        self.tail = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A DMA stream in circular mode as RM0090 §10.3.9/§10.5.6 describe it: each transfer
    /// writes at N − NDTR and decrements NDTR; after the transfer that brings it to 0 it is
    /// reloaded with N.
    struct Stream<const N: usize> {
        buf: [u8; N],
        ndtr: u32,
    }

    impl<const N: usize> Stream<N> {
        fn new() -> Self {
            Self {
                buf: [0; N],
                ndtr: N as u32,
            }
        }
        /// The stream re-armed after a stop: NDTR reloaded with N, so it writes slot 0 next.
        fn rearm(&mut self) {
            self.ndtr = N as u32;
        }
        fn receive(&mut self, bytes: &[u8]) {
            for &b in bytes {
                self.buf[N - self.ndtr as usize] = b;
                self.ndtr -= 1;
                if self.ndtr == 0 {
                    self.ndtr = N as u32;
                }
            }
        }
    }

    fn drain<const N: usize>(ring: &mut RxRing<N>, s: &Stream<N>) -> Vec<u8> {
        let mut out = Vec::new();
        while let Some(b) = ring.next(s.ndtr, |i| s.buf[i]) {
            out.push(b);
        }
        out
    }

    #[test]
    fn bytes_come_out_in_order_across_many_wrap_arounds() {
        let mut s = Stream::<8>::new();
        let mut ring = RxRing::<8>::new();
        let mut next = 0u8;
        let mut expected = Vec::new();
        let mut got = Vec::new();
        // Chunks of 1..=7 bytes (never a full round unread), about 200 rounds of the buffer.
        for k in 0..400usize {
            let len = 1 + k % 7;
            let chunk: Vec<u8> = (0..len)
                .map(|_| {
                    next = next.wrapping_add(1);
                    next
                })
                .collect();
            s.receive(&chunk);
            expected.extend_from_slice(&chunk);
            got.extend(drain(&mut ring, &s));
        }
        assert_eq!(got, expected);
        assert!(expected.len() > 8 * 190);
    }

    #[test]
    fn nothing_is_read_until_the_dma_writes_and_a_caught_up_reader_reads_nothing() {
        let mut s = Stream::<16>::new();
        let mut ring = RxRing::<16>::new();
        assert_eq!(drain(&mut ring, &s), Vec::<u8>::new());
        s.receive(&[0xAA]);
        assert_eq!(drain(&mut ring, &s), vec![0xAA]);
        assert_eq!(drain(&mut ring, &s), Vec::<u8>::new());
    }

    #[test]
    fn n_minus_one_unread_bytes_ending_exactly_at_the_wrap_are_all_delivered() {
        let mut s = Stream::<8>::new();
        let mut ring = RxRing::<8>::new();
        s.receive(&[1]);
        assert_eq!(drain(&mut ring, &s), vec![1]);
        // 7 bytes: slots 1..=7, the last transfer of the round: NDTR goes 1 → 0 → reload 8.
        s.receive(&[2, 3, 4, 5, 6, 7, 8]);
        assert_eq!(s.ndtr, 8);
        assert_eq!(drain(&mut ring, &s), vec![2, 3, 4, 5, 6, 7, 8]);
    }

    #[test]
    fn ndtr_read_between_the_last_transfer_and_its_reload_is_position_zero() {
        assert_eq!(RxRing::<8>::head(0), 0);
        assert_eq!(RxRing::<8>::head(8), 0);
        assert_eq!(RxRing::<8>::head(1), 7);
        assert_eq!(RxRing::<8>::head(9), 0);
        let mut ring = RxRing::<8>::new();
        let buf = [10u8, 11, 12, 13, 14, 15, 16, 17];
        // The DMA wrote slots 0..=7 and NDTR shows the transient 0: all 8 would be a full
        // round, which reads as nothing (the documented limit); after 7 it reads 7.
        let mut got = Vec::new();
        while let Some(b) = ring.next(1, |i| buf[i]) {
            got.push(b);
        }
        assert_eq!(got, vec![10, 11, 12, 13, 14, 15, 16]);
        assert_eq!(ring.next(0, |i| buf[i]), Some(17));
        assert_eq!(ring.next(0, |i| buf[i]), None);
    }

    #[test]
    fn a_full_round_unread_is_lost_as_the_module_says() {
        let mut s = Stream::<8>::new();
        let mut ring = RxRing::<8>::new();
        s.receive(&[1, 2, 3, 4, 5, 6, 7, 8]);
        assert_eq!(drain(&mut ring, &s), Vec::<u8>::new());
        // The reader is still in step for what comes next.
        s.receive(&[9]);
        assert_eq!(drain(&mut ring, &s), vec![9]);
    }

    #[test]
    fn after_a_stopped_stream_is_rearmed_new_bytes_come_out_and_old_ones_are_not_replayed() {
        let mut s = Stream::<8>::new();
        let mut ring = RxRing::<8>::new();
        s.receive(&[1, 2, 3]);
        assert_eq!(drain(&mut ring, &s), vec![1, 2, 3]);
        // Two more bytes, then a transfer error stops the stream mid-round: NDTR stays at 3.
        s.receive(&[4, 5]);
        assert_eq!(s.ndtr, 3);
        // The bytes written before the stop are still delivered...
        assert_eq!(drain(&mut ring, &s), vec![4, 5]);
        // ...then the firmware re-arms the stream from slot 0 and the reader follows it.
        s.rearm();
        ring.restart();
        assert_eq!(drain(&mut ring, &s), Vec::<u8>::new());
        s.receive(&[6, 7, 8, 9, 10, 11, 12]);
        assert_eq!(drain(&mut ring, &s), vec![6, 7, 8, 9, 10, 11, 12]);
        // Without the reader's restart it would have read slots 5.. (stale bytes) and lost the
        // new ones written at 0..: the same stream, a reader that did not follow.
        let mut s = Stream::<8>::new();
        let mut lost = RxRing::<8>::new();
        s.receive(&[1, 2, 3, 4, 5]);
        drain(&mut lost, &s);
        s.rearm();
        s.receive(&[6, 7]);
        assert_ne!(drain(&mut lost, &s), vec![6, 7]);
    }
}
