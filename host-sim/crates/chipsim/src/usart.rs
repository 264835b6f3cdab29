//! Register-level model of the receive side of the STM32F405's USART1 and of the DMA stream
//! that empties it, written from RM0090 (Rev 19):
//!
//! - §30.3.3 "Receiver": a received byte is moved from the shift register to USART_DR and sets
//!   RXNE; "when a character is received while RXNE is set" the overrun error ORE is set, the
//!   byte in DR is kept and the new one, in the shift register, is lost.
//! - §30.6.1 "Status register (USART_SR)": RXNE is cleared by a read of USART_DR; ORE (and FE,
//!   NF) by a read of USART_SR followed by a read of USART_DR.
//! - §30.3.13 "Continuous communication using DMA" and §30.6.6 (USART_CR3.DMAR): with DMAR set,
//!   every RXNE is a DMA request and the DMA reads USART_DR.
//! - §10.3.9 "Circular mode" and §10.5.6 (DMA_SxNDTR): the stream writes at N − NDTR,
//!   decrements NDTR per transfer and reloads N after the last one of a round.
//! - §3.5 (flash stall): only flash reads wait during a flash erase or program; DMA2 moving a
//!   byte from USART1 (APB2) to SRAM1 reads no flash, so a stalled core does not stall it.
//!
//! Line timing: 8N1 is 10 bit times per byte, one byte every 86.8 µs at 115,200 Bd.

/// Baud rate of the board's UART (docs/protocol.md).
pub const BAUD: u64 = 115_200;
/// Bit times per byte on an 8N1 line: start, 8 data, stop.
pub const BITS_PER_BYTE: u64 = 10;

/// The instant the `k`-th byte (0-based) of a back-to-back burst starting at `start_us` has
/// been received completely (its stop bit sampled), µs, rounded up.
pub fn byte_done_us(start_us: u64, k: u64) -> u64 {
    start_us + ((k + 1) * BITS_PER_BYTE * 1_000_000).div_ceil(BAUD)
}

/// USART_SR bits (RM0090 §30.6.1).
pub mod sr {
    /// Overrun error.
    pub const ORE: u32 = 1 << 3;
    /// Read data register not empty.
    pub const RXNE: u32 = 1 << 5;
}

/// USART1's receiver, with a circular DMA stream of `N` bytes behind it when DMAR is set.
pub struct UsartRx<const N: usize> {
    dr: u8,
    rxne: bool,
    ore: bool,
    /// An SR read that saw ORE, waiting for the DR read that completes the clearing sequence.
    sr_read_with_ore: bool,
    /// USART_CR3.DMAR: received bytes are DMA requests.
    pub dmar: bool,
    /// The DMA stream's memory buffer (the firmware's `RX_RING`).
    pub ring: [u8; N],
    /// DMA_SxNDTR: transfers left in this round.
    ndtr: u32,
    /// Bytes that completed on the line.
    pub received: u64,
    /// Bytes lost to an overrun (the shift register overwritten while RXNE was set).
    pub overrun_bytes: u64,
}

impl<const N: usize> Default for UsartRx<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> UsartRx<N> {
    /// After reset: DR empty, the stream enabled with NDTR = N and DMAR off.
    pub fn new() -> Self {
        Self {
            dr: 0,
            rxne: false,
            ore: false,
            sr_read_with_ore: false,
            dmar: false,
            ring: [0; N],
            ndtr: N as u32,
            received: 0,
            overrun_bytes: 0,
        }
    }

    /// A byte's stop bit was sampled: it goes to DR, or is lost with ORE if DR still holds an
    /// unread byte (§30.3.3). With DMAR the DMA request follows at once and the stream takes DR
    /// into the ring (a few AHB cycles, far below one byte time; a stalled core does not delay
    /// it, §3.5).
    pub fn byte_received(&mut self, byte: u8) {
        self.received += 1;
        if self.rxne {
            self.ore = true;
            self.overrun_bytes += 1;
        } else {
            self.dr = byte;
            self.rxne = true;
        }
        if self.dmar && self.rxne {
            let b = self.read_dr();
            let pos = N - self.ndtr as usize;
            self.ring[pos] = b;
            self.ndtr -= 1;
            if self.ndtr == 0 {
                self.ndtr = N as u32;
            }
        }
    }

    /// A read of USART_SR (the first half of clearing ORE).
    pub fn read_sr(&mut self) -> u32 {
        self.sr_read_with_ore = self.ore;
        (if self.ore { sr::ORE } else { 0 }) | (if self.rxne { sr::RXNE } else { 0 })
    }

    /// A read of USART_DR: clears RXNE, and ORE after an SR read that saw it.
    pub fn read_dr(&mut self) -> u8 {
        self.rxne = false;
        if self.sr_read_with_ore {
            self.ore = false;
            self.sr_read_with_ore = false;
        }
        self.dr
    }

    /// DMA_SxNDTR as the firmware reads it.
    pub fn ndtr(&self) -> u32 {
        self.ndtr
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_byte_arrives_every_86_8_us_at_115200_baud() {
        assert_eq!(byte_done_us(0, 0), 87);
        assert_eq!(byte_done_us(0, 9), 869);
        assert_eq!(byte_done_us(0, 115_199), 10_000_000);
    }

    #[test]
    fn a_byte_not_read_before_the_next_one_completes_sets_ore_and_the_new_byte_is_lost() {
        let mut u = UsartRx::<8>::new();
        u.byte_received(1);
        u.byte_received(2);
        assert_eq!(u.overrun_bytes, 1);
        let s = u.read_sr();
        assert_eq!(s, sr::ORE | sr::RXNE);
        // The byte in DR is the old one; reading it completes the clearing sequence.
        assert_eq!(u.read_dr(), 1);
        assert_eq!(u.read_sr(), 0);
        u.byte_received(3);
        assert_eq!(u.read_dr(), 3);
        assert_eq!(u.overrun_bytes, 1);
    }

    #[test]
    fn a_dr_read_without_the_sr_read_first_leaves_ore_set() {
        let mut u = UsartRx::<8>::new();
        u.byte_received(1);
        u.byte_received(2);
        u.read_dr();
        assert_eq!(u.read_sr() & sr::ORE, sr::ORE);
    }

    #[test]
    fn with_dmar_every_byte_goes_to_the_ring_round_and_round_and_none_overruns() {
        let mut u = UsartRx::<4>::new();
        u.dmar = true;
        for b in 1..=6u8 {
            u.byte_received(b);
        }
        assert_eq!(u.overrun_bytes, 0);
        assert_eq!(u.ring, [5, 6, 3, 4]);
        assert_eq!(u.ndtr(), 2);
    }
}
