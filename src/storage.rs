//! Power-fail-safe calibration storage: three slots (A/B/C) on any `embedded-storage` NOR flash.
//!
//! The board keeps its calibration table in internal flash (STM32F405 sectors 9, 10 and 11);
//! the QEMU board keeps it in [`RamFlash`]. The newest valid slot holds the active table, the
//! newest valid slot with a *different* table holds the rollback ("previous") table, and the
//! third slot is the spare: a new table (or a rollback, which re-commits the previous table) is
//! written to the spare only, read back, and only then made valid by programming a commit
//! marker as the very last step. So a power cut at any point leaves either the old or the new
//! table active with its rollback table intact, never none and never a mix; and the spare can
//! be erased ahead of the next upload ([`CalibrationStore::prepare_commit`]) without losing
//! anything. The layout and the reasoning per step are in docs/storage.md.
//!
//! Slot layout (offsets inside a slot; `align` = lcm(WRITE_SIZE, READ_SIZE, 4)):
//!
//! | offset | size | field |
//! |---:|---:|---|
//! | 0 | 4 | slot magic `ACSL` |
//! | 4 | 4 | sequence number, u32 LE |
//! | 8 | 4 | table length, u32 LE (426) |
//! | 12 | 4 | CRC-32C over bytes 0..12 and the table, u32 LE |
//! | 16 | 426 | the encoded [`CalibrationTable`] (with its own CRC-32) |
//! | 442 | to `align` | padding, left erased (0xFF) |
//! | round_up(442, align) | round_up(4, WRITE_SIZE) | commit marker `0xC33C_5AA5` LE, rest 0xFF |

mod ram_flash;
#[cfg(test)]
mod tests;
mod watched;

pub use ram_flash::{RamFlash, RamFlashError};
pub use watched::{Watched, Watcher};

use embedded_storage::nor_flash::NorFlash;

use crate::table::{table_id, CalibrationTable, TableError, ENCODED_LEN};

/// First four bytes of a written slot.
pub const SLOT_MAGIC: [u8; 4] = *b"ACSL";
/// Bytes of the slot header (magic, sequence, length, CRC).
pub const SLOT_HEADER_LEN: usize = 16;
/// The commit marker. Sixteen one bits and sixteen zero bits: an erased word (all ones) is not
/// the marker, and because NOR programming only clears bits, a program cut short leaves some of
/// the sixteen zeros still at one, which is not the marker either. The marker is therefore
/// either fully programmed or detectably absent.
pub const COMMIT_MARKER: u32 = 0xC33C_5AA5;
/// CRC of the slot header and table. CRC-32C (Castagnoli), deliberately *not* the table's own
/// CRC-32/ISO-HDLC: a CRC over a block that ends with a correct CRC of the same polynomial has
/// a value independent of the block's contents (the residue property), so the same polynomial
/// would add no check on the table bytes.
// Bitwise (no 1 KiB table in flash): it runs only at boot and at a commit, over a slot header
// and a table (< 512 bytes, ≈ 30 k instructions).
pub const SLOT_CRC: crc::Crc<u32, crc::NoTable> =
    crc::Crc::<u32, crc::NoTable>::new(&crc::CRC_32_ISCSI);
/// Largest WRITE_SIZE/READ_SIZE alignment supported (sizes the stack buffers).
pub const MAX_ALIGN: usize = 64;
/// Bytes of header plus table before padding.
const IMAGE_DATA_LEN: usize = SLOT_HEADER_LEN + ENCODED_LEN;
/// Buffer for the header, table and padding at the largest supported alignment.
const IMAGE_BUF_LEN: usize = round_up(IMAGE_DATA_LEN, MAX_ALIGN);
/// Sequence number of the first table written to factory-empty flash.
const FIRST_SEQUENCE: u32 = 1;

const fn round_up(n: usize, align: usize) -> usize {
    n.div_ceil(align) * align
}

const fn gcd(a: usize, b: usize) -> usize {
    let (mut a, mut b) = (a, b);
    while b != 0 {
        let t = a % b;
        a = b;
        b = t;
    }
    a
}

const fn lcm(a: usize, b: usize) -> usize {
    a / gcd(a, b) * b
}

/// `a` is newer than `b` in serial-number arithmetic (RFC 1982 style): the forward distance from
/// `b` to `a` is non-zero and less than half the sequence space. Consecutive commits differ by
/// one, so a wrap from 0xFFFF_FFFF to 0 still orders correctly.
pub fn sequence_newer(a: u32, b: u32) -> bool {
    (a.wrapping_sub(b) as i32) > 0
}

/// Number of slots: active, previous (rollback) and a spare that the next commit writes.
pub const SLOT_COUNT: usize = 3;

/// One of the three slots.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slot {
    /// First slot.
    A,
    /// Second slot.
    B,
    /// Third slot.
    C,
}

impl Slot {
    /// Every slot, in scan order (the order that breaks ties).
    pub const ALL: [Slot; SLOT_COUNT] = [Slot::A, Slot::B, Slot::C];

    /// 0 for A, 1 for B, 2 for C (the wire's FlashVerify detail).
    pub const fn index(self) -> usize {
        self as usize
    }
}

/// Where the slots lie in the flash device (offsets relative to the device's start).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SlotLayout {
    /// Offsets of slots A, B and C, multiples of ERASE_SIZE.
    pub slot_offsets: [u32; SLOT_COUNT],
    /// Bytes per slot, a non-zero multiple of ERASE_SIZE.
    pub slot_len: u32,
}

impl SlotLayout {
    /// STM32F405 sectors 9 (0x080A_0000), 10 (0x080C_0000) and 11 (0x080E_0000), 128 KiB
    /// each, as offsets from the flash base 0x0800_0000. memory.x keeps the program below
    /// 0x080A_0000.
    pub const STM32F405_SECTORS_9_11: SlotLayout = SlotLayout {
        slot_offsets: [0x000A_0000, 0x000C_0000, 0x000E_0000],
        slot_len: 0x0002_0000,
    };

    /// Slots A, B and C back to back from offset 0 (RAM flash, test flashes).
    pub const fn consecutive(slot_len: u32) -> SlotLayout {
        SlotLayout {
            slot_offsets: [0, slot_len, 2 * slot_len],
            slot_len,
        }
    }

    fn offset(&self, slot: Slot) -> u32 {
        match slot {
            Slot::A => self.slot_offsets[0],
            Slot::B => self.slot_offsets[1],
            Slot::C => self.slot_offsets[2],
        }
    }
}

/// Why a slot layout does not fit the flash.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LayoutError {
    /// lcm(WRITE_SIZE, READ_SIZE, 4) exceeds [`MAX_ALIGN`].
    AlignmentTooLarge,
    /// A slot offset or the slot length is not a multiple of ERASE_SIZE, or the length is zero.
    NotEraseAligned,
    /// A slot cannot hold the header, table and commit marker.
    SlotTooSmall,
    /// Two slots overlap.
    Overlap,
    /// A slot extends past the end of the flash.
    OutOfBounds,
}

/// Why a storage operation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StorageError<E> {
    /// The flash driver reported an error (or, in the power-cut tests, the power went away).
    Flash(E),
    /// The table was refused by [`CalibrationTable::decode`]; flash was not touched.
    Table(TableError),
    /// What was read back from the slot differs from what was written; the slot was left
    /// without a commit marker, so the active table is unchanged.
    Verify(Slot),
    /// Neither slot holds a valid table (factory-empty flash or both corrupted).
    NoValidSlot,
    /// Rollback asked for, but no valid slot holds a table other than the active one.
    NoPreviousSlot,
    /// The slot layout does not fit the flash geometry.
    Layout(LayoutError),
}

/// A valid, committed slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SlotInfo {
    /// Which slot.
    pub slot: Slot,
    /// Its sequence number.
    pub sequence: u32,
    /// The id (CRC-32) of the table it holds.
    pub table_id: u32,
}

/// Why a slot that is not blank is not valid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SlotFault {
    /// The header does not start with `ACSL`.
    BadMagic,
    /// The length field is not the table length of this format.
    BadLength(u32),
    /// The commit marker is absent or partly programmed: the write never finished.
    NoCommitMarker,
    /// The slot CRC-32C does not match header and table.
    BadCrc,
    /// The table inside does not decode or validate.
    Table(TableError),
}

/// What a slot holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SlotState {
    /// Header and marker are erased: never written, or erased and not yet programmed.
    Blank,
    /// A committed table.
    Valid(SlotInfo),
    /// Written but not valid.
    Invalid(SlotFault),
}

/// The valid slots found by a scan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ValidSlots {
    /// The valid slot with the newest sequence number (the active one).
    pub newest: Option<SlotInfo>,
    /// The newest valid slot whose table differs from the active one (the rollback table).
    pub previous: Option<SlotInfo>,
}

/// Result of classifying every slot.
#[derive(Debug, Clone, Copy)]
struct Scan {
    /// The valid slot with the newest sequence number.
    newest: Option<SlotInfo>,
    /// The newest valid slot holding a table other than `newest`'s.
    previous: Option<SlotInfo>,
    /// Each slot's state, in [`Slot::ALL`] order.
    states: [SlotState; SLOT_COUNT],
}

/// Derived from the flash type's sizes once, at construction.
#[derive(Debug, Clone, Copy)]
struct Geometry {
    /// Bytes programmed for header, table and padding (a multiple of `align`).
    image_len: usize,
    /// Offset of the commit marker inside a slot (= `image_len`).
    marker_offset: u32,
    /// Bytes programmed for the marker (a multiple of `align`).
    marker_len: usize,
}

/// The three-slot calibration store. Owns the flash; [`CalibrationStore::into_flash`] gives it
/// back.
#[derive(Clone)]
pub struct CalibrationStore<F> {
    flash: F,
    layout: SlotLayout,
    geometry: Geometry,
    active: Option<SlotInfo>,
    /// A slot whose erase *completed* in this power cycle and that nothing has written since
    /// ([`CalibrationStore::prepare_commit`]). Kept in RAM only, so an erase cut short by a
    /// power loss is never trusted.
    erased: Option<Slot>,
    /// Sector erases run since boot (each one stalls a single-bank MCU: the service counts the
    /// stall time around the operations that erased).
    erases: u32,
}

impl<F: NorFlash> CalibrationStore<F> {
    /// Checks the layout against the flash geometry, then scans both slots ([`Self::boot`]).
    /// Factory-empty flash is not an error: [`Self::active`] is then `None` and the firmware
    /// flags NO_CALIBRATION.
    pub fn new(flash: F, layout: SlotLayout) -> Result<Self, StorageError<F::Error>> {
        let geometry = Self::geometry(&flash, &layout).map_err(StorageError::Layout)?;
        let mut store = CalibrationStore {
            flash,
            layout,
            geometry,
            active: None,
            erased: None,
            erases: 0,
        };
        store.boot()?;
        Ok(store)
    }

    fn geometry(flash: &F, layout: &SlotLayout) -> Result<Geometry, LayoutError> {
        let align = lcm(lcm(F::WRITE_SIZE.max(1), F::READ_SIZE.max(1)), 4);
        if align > MAX_ALIGN {
            return Err(LayoutError::AlignmentTooLarge);
        }
        let image_len = round_up(IMAGE_DATA_LEN, align);
        let marker_len = round_up(4, align);
        if image_len > IMAGE_BUF_LEN || marker_len > MAX_ALIGN {
            return Err(LayoutError::AlignmentTooLarge);
        }
        let erase = F::ERASE_SIZE.max(1) as u64;
        let len = u64::from(layout.slot_len);
        let offsets = layout.slot_offsets.map(u64::from);
        if len == 0 || len % erase != 0 || offsets.iter().any(|o| o % erase != 0) {
            return Err(LayoutError::NotEraseAligned);
        }
        if ((image_len + marker_len) as u64) > len {
            return Err(LayoutError::SlotTooSmall);
        }
        for (i, a) in offsets.iter().enumerate() {
            for b in offsets.iter().skip(i + 1) {
                if *a < b + len && *b < a + len {
                    return Err(LayoutError::Overlap);
                }
            }
        }
        let capacity = flash.capacity() as u64;
        if offsets.iter().any(|o| o + len > capacity) {
            return Err(LayoutError::OutOfBounds);
        }
        Ok(Geometry {
            image_len,
            marker_offset: image_len as u32,
            marker_len,
        })
    }

    /// The active slot found by the last scan or commit.
    pub fn active(&self) -> Option<SlotInfo> {
        self.active
    }

    /// Gives the flash back (the tests "reboot" by building a new store on it).
    pub fn into_flash(self) -> F {
        self.flash
    }

    /// The flash, for tests that inject faults into it while the store holds it.
    #[cfg(test)]
    pub(crate) fn flash_mut(&mut self) -> &mut F {
        &mut self.flash
    }

    /// Scans both slots and makes the newest valid one active: highest sequence number in
    /// serial-number arithmetic among the slots with magic, length, commit marker, slot CRC and
    /// a table that decodes. Returns `None` when neither is valid.
    pub fn boot(&mut self) -> Result<Option<SlotInfo>, StorageError<F::Error>> {
        let newest = self.scan()?.newest;
        self.active = newest;
        Ok(newest)
    }

    /// Reads and classifies one slot.
    pub fn slot_state(&mut self, slot: Slot) -> Result<SlotState, StorageError<F::Error>> {
        let mut image = [0u8; IMAGE_BUF_LEN];
        self.read_slot(slot, &mut image)
    }

    /// Re-scans and decodes the table of the newest valid slot. Re-reading (rather than
    /// trusting the slot chosen at boot) means a slot that has rotted since boot is skipped.
    pub fn load_active(&mut self) -> Result<(SlotInfo, CalibrationTable), StorageError<F::Error>> {
        let mut bytes = [0u8; ENCODED_LEN];
        let info = self.read_active_bytes(&mut bytes)?;
        let table = CalibrationTable::decode(&bytes).map_err(StorageError::Table)?;
        Ok((info, table))
    }

    /// Copies the encoded table of the newest valid slot into `out` (for read-back over UART).
    pub fn read_active_bytes(
        &mut self,
        out: &mut [u8; ENCODED_LEN],
    ) -> Result<SlotInfo, StorageError<F::Error>> {
        let info = self.boot()?.ok_or(StorageError::NoValidSlot)?;
        self.read_table_bytes(info.slot, out)?;
        Ok(info)
    }

    /// Stores a new table and makes it active.
    ///
    /// 1. Validate with [`CalibrationTable::decode`]; a refused table touches nothing.
    /// 2. Scan; the target is the spare: neither the active slot nor the rollback slot.
    /// 3. Erase the target (unless [`Self::prepare_commit`] already did in this power cycle).
    /// 4. Program header and table.
    /// 5. Read back and compare; check the marker area is still erased.
    /// 6. Program the commit marker — the single step that makes the new slot valid.
    /// 7. Re-read the slot and check it classifies as valid with the new sequence.
    ///
    /// A power cut before step 6 completes leaves the old table active (the new slot has no
    /// valid marker); after it, the new table (its sequence is one above the old). The active
    /// and the rollback slot are never written, so the rollback table survives too.
    pub fn commit(&mut self, table: &[u8]) -> Result<SlotInfo, StorageError<F::Error>> {
        CalibrationTable::decode(table).map_err(StorageError::Table)?;
        let mut bytes = [0u8; ENCODED_LEN];
        let src = table
            .get(..ENCODED_LEN)
            .ok_or(StorageError::Table(TableError::BadLength {
                expected: ENCODED_LEN as u32,
                found: table.len() as u32,
            }))?;
        bytes.copy_from_slice(src);
        let scan = self.scan()?;
        self.active = scan.newest;
        let target = self.spare(&scan);
        self.write_slot(target, next_sequence(scan.newest), &bytes)
    }

    /// Erases the slot the next [`Self::commit`] (or rollback) will write — the spare, which
    /// holds neither the active nor the rollback table — so the commit itself skips the erase.
    /// On the STM32F405 a 128 KiB sector erase takes seconds (datasheet tERASE128KB) while
    /// programming a table takes milliseconds: the firmware calls this right after a commit or
    /// a rollback and at boot ("erase ahead"), so an upload never waits for an erase. Power-fail
    /// safe and loses nothing: the spare is by construction not needed. Returns the slot, and
    /// does nothing when that slot's erase already completed in this power cycle.
    pub fn prepare_commit(&mut self) -> Result<Slot, StorageError<F::Error>> {
        let scan = self.scan()?;
        self.active = scan.newest;
        let target = self.spare(&scan);
        if self.erased == Some(target) {
            return Ok(target);
        }
        // Cleared before the erase and set only after it completes: a failed or interrupted
        // erase must be redone by the commit.
        self.erased = None;
        self.erase_unless_blank(target)?;
        self.erased = Some(target);
        Ok(target)
    }

    /// Sector erases run since boot.
    pub fn erase_count(&self) -> u32 {
        self.erases
    }

    /// Erases `slot` unless everything a commit programs there (image and marker) already
    /// reads erased: an erase stalls the whole MCU for up to seconds, a blank check costs a
    /// read of a few hundred bytes. Cells outside that area are never programmed or read, so
    /// whatever an interrupted erase left there does not matter.
    fn erase_unless_blank(&mut self, slot: Slot) -> Result<(), StorageError<F::Error>> {
        let base = self.layout.offset(slot);
        let len = self.geometry.image_len + self.geometry.marker_len;
        let mut chunk = [0u8; 64];
        let mut at = 0usize;
        let mut blank = true;
        while blank && at < len {
            let n = chunk.len().min(len - at);
            let part = chunk.get_mut(..n).unwrap_or(&mut []);
            self.flash
                .read(base + at as u32, part)
                .map_err(StorageError::Flash)?;
            blank = part.iter().all(|b| *b == 0xFF);
            at += n;
        }
        if blank {
            return Ok(());
        }
        self.erases = self.erases.wrapping_add(1);
        self.flash
            .erase(base, base + self.layout.slot_len)
            .map_err(StorageError::Flash)
    }

    /// Whether the next commit's target is known erased (an erase completed in this power
    /// cycle and nothing was written since): then a commit costs programming time only.
    pub fn spare_erased(&mut self) -> Result<bool, StorageError<F::Error>> {
        let scan = self.scan()?;
        Ok(self.erased == Some(self.spare(&scan)))
    }

    /// The active and the rollback slot (re-scanned). The service restores the rollback table
    /// from `previous` at boot.
    pub fn valid_slots(&mut self) -> Result<ValidSlots, StorageError<F::Error>> {
        let Scan {
            newest, previous, ..
        } = self.scan()?;
        self.active = newest;
        Ok(ValidSlots { newest, previous })
    }

    /// Decodes the table of a slot that [`Self::valid_slots`] reported valid. Decoded again
    /// rather than trusted: the slot may have changed since the scan.
    pub fn load_slot(&mut self, slot: Slot) -> Result<CalibrationTable, StorageError<F::Error>> {
        let mut bytes = [0u8; ENCODED_LEN];
        self.read_table_bytes(slot, &mut bytes)?;
        CalibrationTable::decode(&bytes).map_err(StorageError::Table)
    }

    /// Rolls back to the rollback table: it is re-committed, with a new sequence number, into
    /// the spare — exactly like an upload of it. Neither the active slot nor the rollback slot
    /// is touched, so a power cut leaves the current table or the rollback target active, and
    /// afterwards the rolled-back-from table is the new rollback table (a second rollback
    /// returns to it, also after a reboot).
    pub fn activate_previous(&mut self) -> Result<SlotInfo, StorageError<F::Error>> {
        let scan = self.scan()?;
        let newest = scan.newest.ok_or(StorageError::NoValidSlot)?;
        self.active = Some(newest);
        let previous = scan.previous.ok_or(StorageError::NoPreviousSlot)?;
        let mut bytes = [0u8; ENCODED_LEN];
        self.read_table_bytes(previous.slot, &mut bytes)?;
        // The bytes come from a slot that just classified valid, but decode again: a slot can
        // change between two reads on failing flash, and nothing unvalidated gets committed.
        CalibrationTable::decode(&bytes).map_err(StorageError::Table)?;
        let target = self.spare(&scan);
        self.write_slot(target, next_sequence(Some(newest)), &bytes)
    }

    /// The slot the next commit writes: neither the active nor the rollback slot. Among the
    /// candidates (at least one, since there are three slots): the one erased ahead in this
    /// power cycle, else a blank one, else an invalid one (a write cut short), else the valid
    /// one with the oldest sequence (a stale copy). Ties go to scan order.
    fn spare(&self, scan: &Scan) -> Slot {
        let used = |s: Slot| {
            scan.newest.map(|i| i.slot) == Some(s) || scan.previous.map(|i| i.slot) == Some(s)
        };
        let rank = |s: Slot| -> (u8, u32) {
            if self.erased == Some(s) {
                return (0, 0);
            }
            match scan.states[s.index()] {
                SlotState::Blank => (1, 0),
                SlotState::Invalid(_) => (2, 0),
                // Older first: distance back from the newest sequence, larger is older.
                SlotState::Valid(i) => (
                    3,
                    u32::MAX
                        - scan
                            .newest
                            .map_or(0, |n| n.sequence.wrapping_sub(i.sequence)),
                ),
            }
        };
        let mut best = None;
        for s in Slot::ALL {
            if used(s) {
                continue;
            }
            best = match best {
                Some(b) if rank(b) <= rank(s) => Some(b),
                _ => Some(s),
            };
        }
        best.unwrap_or(Slot::C)
    }

    /// Every slot classified: the newest valid one, the newest valid one with another table,
    /// and each state.
    fn scan(&mut self) -> Result<Scan, StorageError<F::Error>> {
        let mut states = [SlotState::Blank; SLOT_COUNT];
        for (state, slot) in states.iter_mut().zip(Slot::ALL) {
            *state = self.slot_state(slot)?;
        }
        let valid = || {
            states.iter().filter_map(|s| match s {
                SlotState::Valid(i) => Some(*i),
                _ => None,
            })
        };
        // Equal sequences cannot come from this code; the first in scan order wins so the
        // choice is stable.
        let newest_of = |it: &mut dyn Iterator<Item = SlotInfo>| {
            it.fold(None, |best: Option<SlotInfo>, i| match best {
                Some(b) if !sequence_newer(i.sequence, b.sequence) => Some(b),
                _ => Some(i),
            })
        };
        let newest = newest_of(&mut valid());
        let previous =
            newest.and_then(|n| newest_of(&mut valid().filter(|i| i.table_id != n.table_id)));
        Ok(Scan {
            newest,
            previous,
            states,
        })
    }

    fn read_slot(
        &mut self,
        slot: Slot,
        image: &mut [u8; IMAGE_BUF_LEN],
    ) -> Result<SlotState, StorageError<F::Error>> {
        let base = self.layout.offset(slot);
        let g = self.geometry;
        let image = image
            .get_mut(..g.image_len)
            .ok_or(StorageError::Layout(LayoutError::AlignmentTooLarge))?;
        self.flash.read(base, image).map_err(StorageError::Flash)?;
        let mut marker_buf = [0u8; MAX_ALIGN];
        let marker = marker_buf
            .get_mut(..g.marker_len)
            .ok_or(StorageError::Layout(LayoutError::AlignmentTooLarge))?;
        self.flash
            .read(base + g.marker_offset, marker)
            .map_err(StorageError::Flash)?;
        Ok(classify(slot, image, marker))
    }

    fn read_table_bytes(
        &mut self,
        slot: Slot,
        out: &mut [u8; ENCODED_LEN],
    ) -> Result<(), StorageError<F::Error>> {
        let mut image = [0u8; IMAGE_BUF_LEN];
        let g = self.geometry;
        let image = image
            .get_mut(..g.image_len)
            .ok_or(StorageError::Layout(LayoutError::AlignmentTooLarge))?;
        self.flash
            .read(self.layout.offset(slot), image)
            .map_err(StorageError::Flash)?;
        let table = image
            .get(SLOT_HEADER_LEN..IMAGE_DATA_LEN)
            .ok_or(StorageError::Layout(LayoutError::AlignmentTooLarge))?;
        out.copy_from_slice(table);
        Ok(())
    }

    /// Erase, program, verify, mark. `table` has been validated by the caller.
    fn write_slot(
        &mut self,
        slot: Slot,
        sequence: u32,
        table: &[u8; ENCODED_LEN],
    ) -> Result<SlotInfo, StorageError<F::Error>> {
        let g = self.geometry;
        let base = self.layout.offset(slot);
        let layout_err = || StorageError::Layout(LayoutError::AlignmentTooLarge);

        let mut image_buf = [0xFFu8; IMAGE_BUF_LEN];
        fill_image(&mut image_buf, sequence, table);
        let image = image_buf.get(..g.image_len).ok_or_else(layout_err)?;

        // Skip the erase only after a completed erase in this power cycle; the read-back below
        // would catch any bit that is not erased anyway (programming can only clear bits).
        if self.erased.take() != Some(slot) {
            self.erase_unless_blank(slot)?;
        }
        self.flash.write(base, image).map_err(StorageError::Flash)?;

        let mut back_buf = [0u8; IMAGE_BUF_LEN];
        let back = back_buf.get_mut(..g.image_len).ok_or_else(layout_err)?;
        self.flash.read(base, back).map_err(StorageError::Flash)?;
        if back != image {
            return Err(StorageError::Verify(slot));
        }
        // The marker area must still be erased, or programming it would AND with stale bits.
        let mut marker_buf = [0xFFu8; MAX_ALIGN];
        let marker = marker_buf.get_mut(..g.marker_len).ok_or_else(layout_err)?;
        self.flash
            .read(base + g.marker_offset, marker)
            .map_err(StorageError::Flash)?;
        if marker.iter().any(|b| *b != 0xFF) {
            return Err(StorageError::Verify(slot));
        }

        let mut marker_buf = [0xFFu8; MAX_ALIGN];
        if let Some(word) = marker_buf.get_mut(..4) {
            word.copy_from_slice(&COMMIT_MARKER.to_le_bytes());
        }
        let marker = marker_buf.get(..g.marker_len).ok_or_else(layout_err)?;
        self.flash
            .write(base + g.marker_offset, marker)
            .map_err(StorageError::Flash)?;

        let expected = SlotInfo {
            slot,
            sequence,
            table_id: table_id(table),
        };
        match self.slot_state(slot)? {
            SlotState::Valid(info) if info == expected => {
                self.active = Some(info);
                Ok(info)
            }
            _ => Err(StorageError::Verify(slot)),
        }
    }
}

/// Sequence number of the next commit: one above the active slot's, or the first one.
fn next_sequence(newest: Option<SlotInfo>) -> u32 {
    newest.map_or(FIRST_SEQUENCE, |n| n.sequence.wrapping_add(1))
}

/// Header, table and erased padding of a slot image.
fn fill_image(image: &mut [u8; IMAGE_BUF_LEN], sequence: u32, table: &[u8; ENCODED_LEN]) {
    let mut header = [0u8; SLOT_HEADER_LEN];
    put(&mut header, 0, &SLOT_MAGIC);
    put(&mut header, 4, &sequence.to_le_bytes());
    put(&mut header, 8, &(ENCODED_LEN as u32).to_le_bytes());
    let crc = slot_crc(header.get(..12).unwrap_or(&[]), table);
    put(&mut header, 12, &crc.to_le_bytes());
    put(image, 0, &header);
    put(image, SLOT_HEADER_LEN, table);
}

fn put(dst: &mut [u8], at: usize, src: &[u8]) {
    if let Some(d) = dst.get_mut(at..at + src.len()) {
        d.copy_from_slice(src);
    }
}

fn le_u32(bytes: &[u8], at: usize) -> Option<u32> {
    let mut b = [0u8; 4];
    b.copy_from_slice(bytes.get(at..at + 4)?);
    Some(u32::from_le_bytes(b))
}

fn slot_crc(header12: &[u8], table: &[u8]) -> u32 {
    let mut digest = SLOT_CRC.digest();
    digest.update(header12);
    digest.update(table);
    digest.finalize()
}

/// Classifies a slot from its image (header, table, padding) and marker bytes.
fn classify(slot: Slot, image: &[u8], marker: &[u8]) -> SlotState {
    let header = image.get(..SLOT_HEADER_LEN).unwrap_or(&[]);
    let marker_word = le_u32(marker, 0);
    if header.iter().all(|b| *b == 0xFF) && marker.iter().all(|b| *b == 0xFF) {
        return SlotState::Blank;
    }
    if header.get(..4) != Some(&SLOT_MAGIC[..]) {
        return SlotState::Invalid(SlotFault::BadMagic);
    }
    let (Some(sequence), Some(len), Some(stored_crc)) =
        (le_u32(header, 4), le_u32(header, 8), le_u32(header, 12))
    else {
        return SlotState::Invalid(SlotFault::BadMagic);
    };
    if len != ENCODED_LEN as u32 {
        return SlotState::Invalid(SlotFault::BadLength(len));
    }
    if marker_word != Some(COMMIT_MARKER) {
        return SlotState::Invalid(SlotFault::NoCommitMarker);
    }
    let Some(table) = image.get(SLOT_HEADER_LEN..IMAGE_DATA_LEN) else {
        return SlotState::Invalid(SlotFault::BadLength(len));
    };
    if slot_crc(header.get(..12).unwrap_or(&[]), table) != stored_crc {
        return SlotState::Invalid(SlotFault::BadCrc);
    }
    if let Err(e) = CalibrationTable::decode(table) {
        return SlotState::Invalid(SlotFault::Table(e));
    }
    let mut encoded = [0u8; ENCODED_LEN];
    encoded.copy_from_slice(table);
    SlotState::Valid(SlotInfo {
        slot,
        sequence,
        table_id: table_id(&encoded),
    })
}
