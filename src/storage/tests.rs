//! Storage tests: a simulated NOR flash that can lose power after any number of erase/program
//! steps, exhaustive power cuts during commit and rollback, bit flips in either slot, and the
//! slot layout checked against an independent re-declaration of docs/storage.md (so a wrong
//! constant in the store cannot agree with itself).

use super::*;
use crate::table::tests::paper_table;
use crate::table::CalibrationTable;
use embedded_storage::nor_flash::{
    check_erase, check_read, check_write, ErrorType, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

// ---- the layout as documented in docs/storage.md, re-declared -----------------------------

const DOC_MAGIC: &[u8; 4] = b"ACSL";
const DOC_MARKER: [u8; 4] = [0xA5, 0x5A, 0x3C, 0xC3]; // 0xC33C_5AA5 little-endian
const DOC_TABLE_LEN: usize = 426;

/// CRC-32C (Castagnoli, reflected polynomial 0x82F63B78), bit by bit, independent of `crc`.
fn doc_crc32c(parts: &[&[u8]]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for part in parts {
        for &byte in *part {
            crc ^= u32::from(byte);
            for _ in 0..8 {
                crc = if crc & 1 != 0 {
                    (crc >> 1) ^ 0x82F6_3B78
                } else {
                    crc >> 1
                };
            }
        }
    }
    !crc
}

/// Marker offset per the doc: header+table rounded up to lcm(WRITE_SIZE, READ_SIZE, 4).
fn doc_marker_offset(align: usize) -> usize {
    (16 + DOC_TABLE_LEN).div_ceil(align) * align
}

/// Writes a committed slot image (header, table, marker) straight into raw flash bytes.
fn doc_write_slot(flash: &mut [u8], base: usize, align: usize, seq: u32, table: &[u8]) {
    let mut header = Vec::new();
    header.extend_from_slice(DOC_MAGIC);
    header.extend_from_slice(&seq.to_le_bytes());
    header.extend_from_slice(&(DOC_TABLE_LEN as u32).to_le_bytes());
    let crc = doc_crc32c(&[&header, table]);
    header.extend_from_slice(&crc.to_le_bytes());
    flash[base..base + 16].copy_from_slice(&header);
    flash[base + 16..base + 16 + DOC_TABLE_LEN].copy_from_slice(table);
    let m = base + doc_marker_offset(align);
    flash[m..m + 4].copy_from_slice(&DOC_MARKER);
}

#[test]
fn doc_crc32c_matches_the_published_check_value() {
    assert_eq!(doc_crc32c(&[b"123456789"]), 0xE306_9283);
    assert_eq!(SLOT_CRC.checksum(b"123456789"), 0xE306_9283);
}

// ---- tables -------------------------------------------------------------------------------

/// Distinct valid tables: the paper table with different serial numbers.
fn table(n: u8) -> [u8; ENCODED_LEN] {
    let mut t = paper_table();
    t.serial = CalibrationTable::serial_from_str(&format!("JN-06 A1212{n}"));
    t.encode()
}

// ---- simulated NOR flash with power cuts --------------------------------------------------

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum SimError {
    PowerCut,
    NotAligned,
    OutOfBounds,
    WouldSetBits,
}

impl NorFlashError for SimError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            SimError::NotAligned => NorFlashErrorKind::NotAligned,
            SimError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            _ => NorFlashErrorKind::Other,
        }
    }
}

impl From<NorFlashErrorKind> for SimError {
    fn from(k: NorFlashErrorKind) -> Self {
        match k {
            NorFlashErrorKind::NotAligned => SimError::NotAligned,
            _ => SimError::OutOfBounds,
        }
    }
}

/// What the operation that is running when the power goes does to the cells.
#[derive(Debug, Clone, Copy)]
enum Cut {
    /// Nothing: the interrupted word/block keeps its old contents.
    Clean,
    /// A random subset of the bits it was changing did change (seeded).
    RandomBits(u64),
}

/// NOR flash with steps counted per erase block and per program word. With a budget of k,
/// the (k+1)-th step is interrupted (see [`Cut`]) and every later operation, reads included,
/// fails until [`SimFlash::reboot`].
#[derive(Clone)]
struct SimFlash<const ERASE: usize, const WRITE: usize, const READ: usize> {
    bytes: Vec<u8>,
    steps: usize,
    budget: Option<usize>,
    cut: Cut,
    rng: u64,
    dead: bool,
    /// (offset, mask): bits that read 1 whatever is programmed (a worn cell).
    stuck_at_one: Vec<(usize, u8)>,
    /// Every operation attempted, in order.
    log: Vec<Access>,
}

/// One flash operation as seen by [`SimFlash`]: (offset, length in bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Access {
    Read(u32, usize),
    Erase(u32, u32),
    Write(u32, usize),
}

impl<const ERASE: usize, const WRITE: usize, const READ: usize> SimFlash<ERASE, WRITE, READ> {
    fn new(capacity: usize) -> Self {
        SimFlash {
            bytes: vec![0xFF; capacity],
            steps: 0,
            budget: None,
            cut: Cut::Clean,
            rng: 1,
            dead: false,
            stuck_at_one: Vec::new(),
            log: Vec::new(),
        }
    }

    fn with_budget(mut self, budget: usize, cut: Cut) -> Self {
        self.budget = Some(budget);
        self.cut = cut;
        if let Cut::RandomBits(seed) = cut {
            self.rng = seed | 1;
        }
        self
    }

    /// Power back on: same cells, no budget.
    fn reboot(mut self) -> Self {
        self.dead = false;
        self.budget = None;
        self
    }

    fn coin(&mut self) -> bool {
        // xorshift64*
        self.rng ^= self.rng >> 12;
        self.rng ^= self.rng << 25;
        self.rng ^= self.rng >> 27;
        self.rng.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 63 == 1
    }

    /// Takes one step; false when the power goes now.
    fn step(&mut self) -> bool {
        match self.budget {
            Some(0) => {
                self.dead = true;
                false
            }
            Some(ref mut n) => {
                *n -= 1;
                self.steps += 1;
                true
            }
            None => {
                self.steps += 1;
                true
            }
        }
    }

    fn apply_stuck(&mut self) {
        for &(off, mask) in &self.stuck_at_one {
            self.bytes[off] |= mask;
        }
    }
}

impl<const E: usize, const W: usize, const R: usize> ErrorType for SimFlash<E, W, R> {
    type Error = SimError;
}

impl<const E: usize, const W: usize, const R: usize> ReadNorFlash for SimFlash<E, W, R> {
    const READ_SIZE: usize = R;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), SimError> {
        self.log.push(Access::Read(offset, bytes.len()));
        if self.dead {
            return Err(SimError::PowerCut);
        }
        check_read(self, offset, bytes.len())?;
        let o = offset as usize;
        bytes.copy_from_slice(&self.bytes[o..o + bytes.len()]);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.bytes.len()
    }
}

impl<const E: usize, const W: usize, const R: usize> NorFlash for SimFlash<E, W, R> {
    const WRITE_SIZE: usize = W;
    const ERASE_SIZE: usize = E;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), SimError> {
        self.log.push(Access::Erase(from, to));
        if self.dead {
            return Err(SimError::PowerCut);
        }
        check_erase(self, from, to)?;
        for block in (from as usize..to as usize).step_by(E) {
            if !self.step() {
                if let Cut::RandomBits(_) = self.cut {
                    for i in block..block + E {
                        for bit in 0..8 {
                            if self.coin() {
                                self.bytes[i] |= 1 << bit;
                            }
                        }
                    }
                }
                return Err(SimError::PowerCut);
            }
            self.bytes[block..block + E].fill(0xFF);
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, data: &[u8]) -> Result<(), SimError> {
        self.log.push(Access::Write(offset, data.len()));
        if self.dead {
            return Err(SimError::PowerCut);
        }
        check_write(self, offset, data.len())?;
        let o = offset as usize;
        // The store always erases before programming: a write that needs a 1 is a bug.
        if self.bytes[o..o + data.len()]
            .iter()
            .zip(data)
            .any(|(old, new)| new & !old != 0)
        {
            return Err(SimError::WouldSetBits);
        }
        for (w, word) in data.chunks(W).enumerate() {
            let at = o + w * W;
            if !self.step() {
                if let Cut::RandomBits(_) = self.cut {
                    for (i, &new) in word.iter().enumerate() {
                        for bit in 0..8 {
                            if new & (1 << bit) == 0 && self.coin() {
                                self.bytes[at + i] &= !(1 << bit);
                            }
                        }
                    }
                    self.apply_stuck();
                }
                return Err(SimError::PowerCut);
            }
            for (i, &new) in word.iter().enumerate() {
                self.bytes[at + i] &= new;
            }
            self.apply_stuck();
        }
        Ok(())
    }
}

// ---- helpers ------------------------------------------------------------------------------

type Small = SimFlash<256, 1, 1>;
const SMALL_LAYOUT: SlotLayout = SlotLayout::consecutive(512);

fn store<const E: usize, const W: usize, const R: usize>(
    flash: SimFlash<E, W, R>,
    layout: SlotLayout,
) -> CalibrationStore<SimFlash<E, W, R>> {
    CalibrationStore::new(flash, layout).expect("store on a healthy flash")
}

/// Flash with the given tables committed in order.
fn flash_with<const E: usize, const W: usize, const R: usize>(
    capacity: usize,
    layout: SlotLayout,
    tables: &[[u8; ENCODED_LEN]],
) -> SimFlash<E, W, R> {
    let mut s = store(SimFlash::<E, W, R>::new(capacity), layout);
    for t in tables {
        s.commit(t).expect("commit on a healthy flash");
    }
    s.into_flash()
}

/// Reboots on the flash and returns the active table's bytes (None: no valid slot).
/// Commits table 3 into slot C of the small layout, which must erase C first, and checks that a
/// reboot finds table 3 active.
fn commit_3_erases_slot_c(mut s: CalibrationStore<SimFlash<256, 1, 1>>) {
    // C held something once (a blank slot is not erased at all).
    s.flash.bytes[1024 + 100] = 0x5A;
    s.flash.log.clear();
    s.commit(&table(3)).unwrap();
    assert!(s.flash.log.contains(&Access::Erase(1024, 1536)));
    let (active, _) = active_after_reboot(s.into_flash(), SMALL_LAYOUT);
    assert_eq!(active, Some(table(3)));
}

fn active_after_reboot<const E: usize, const W: usize, const R: usize>(
    flash: SimFlash<E, W, R>,
    layout: SlotLayout,
) -> (Option<[u8; ENCODED_LEN]>, SimFlash<E, W, R>) {
    let mut s = store(flash.reboot(), layout);
    let mut out = [0u8; ENCODED_LEN];
    let found = match s.read_active_bytes(&mut out) {
        Ok(_) => {
            // The table the firmware would use must decode, not just match bytes.
            s.load_active().expect("active table decodes");
            Some(out)
        }
        Err(StorageError::NoValidSlot) => None,
        Err(e) => panic!("boot failed: {e:?}"),
    };
    (found, s.into_flash())
}

#[derive(Clone, Copy)]
enum Op<'a> {
    Commit(&'a [u8; ENCODED_LEN]),
    /// `prepare_commit` then `commit` on the same store (the firmware's upload path).
    PreparedCommit(&'a [u8; ENCODED_LEN]),
    Rollback,
}

fn run<const E: usize, const W: usize, const R: usize>(
    flash: SimFlash<E, W, R>,
    layout: SlotLayout,
    op: Op,
) -> (Result<SlotInfo, StorageError<SimError>>, SimFlash<E, W, R>) {
    let mut s = store(flash, layout);
    let r = match op {
        Op::Commit(t) => s.commit(t),
        Op::PreparedCommit(t) => s.prepare_commit().and_then(|_| s.commit(t)),
        Op::Rollback => s.activate_previous(),
    };
    (r, s.into_flash())
}

const CUTS: [Cut; 4] = [
    Cut::Clean,
    Cut::RandomBits(0x9E37_79B9_7F4A_7C15),
    Cut::RandomBits(0xD1B5_4A32_D192_ED03),
    Cut::RandomBits(0x8CB9_2BA7_2F3D_8DD7),
];

/// Cuts the power at every erase/program step of `op` on `initial`, for each [`Cut`] model,
/// reboots, and checks the active table is exactly `old` or exactly `new` — and `old` for
/// every cut before the commit marker's first word. After each cut, a retried `op` must
/// succeed (a half-written slot does not block recovery). Returns the cut points tried.
fn exhaustive_cuts<const E: usize, const W: usize, const R: usize>(
    initial: &SimFlash<E, W, R>,
    layout: SlotLayout,
    op: Op,
    old: &[u8; ENCODED_LEN],
    new: &[u8; ENCODED_LEN],
) -> usize {
    let mut counted = initial.clone();
    counted.steps = 0;
    let (r, done) = run(counted, layout, op);
    r.expect("uncut operation succeeds");
    let total = done.steps;
    let (after, _) = active_after_reboot(done, layout);
    assert_eq!(
        after.as_ref(),
        Some(new),
        "uncut operation activates the new table"
    );
    let align = lcm(lcm(W, R), 4);
    let marker_steps = align.div_ceil(W);
    let first_marker_step = total - marker_steps;

    let mut tried = 0;
    for cut in CUTS {
        for k in 0..total {
            let (r, cut_flash) = run(initial.clone().with_budget(k, cut), layout, op);
            assert_eq!(
                r,
                Err(StorageError::Flash(SimError::PowerCut)),
                "cut at {k}"
            );
            let (active, flash) = active_after_reboot(cut_flash, layout);
            let active = active.unwrap_or_else(|| panic!("no table after cut at {k}/{total}"));
            assert!(
                active == *old || active == *new,
                "mixed table after cut at {k}/{total} ({cut:?})"
            );
            // A rollback may legitimately land on its target as soon as the newer slot's
            // erase begins; a commit may not show the new table before its marker.
            if !matches!(op, Op::Rollback) && k < first_marker_step {
                assert!(active == *old, "new table active before its marker ({k})");
            }
            // Recovery: the same operation, retried after the reboot, completes.
            if active == *old {
                let (r, flash) = run(flash, layout, op);
                r.unwrap_or_else(|e| panic!("retry after cut at {k} failed: {e:?}"));
                let (after, _) = active_after_reboot(flash, layout);
                assert_eq!(after.as_ref(), Some(new), "retry after cut at {k}");
            }
            tried += 1;
        }
    }
    tried
}

// ---- power cuts ---------------------------------------------------------------------------

fn cuts_for_geometry<const E: usize, const W: usize, const R: usize>(
    capacity: usize,
    layout: SlotLayout,
) -> usize {
    let (t1, t2, t3, t4) = (table(1), table(2), table(3), table(4));
    let mut tried = 0;
    // From one table.
    let one = flash_with::<E, W, R>(capacity, layout, &[t1]);
    tried += exhaustive_cuts(&one, layout, Op::Commit(&t2), &t1, &t2);
    // From two tables, then repeated commits so each slot is the target in turn.
    let mut state = flash_with::<E, W, R>(capacity, layout, &[t1, t2]);
    let mut old = t2;
    for new in [t3, t4, t1, t2] {
        tried += exhaustive_cuts(&state, layout, Op::Commit(&new), &old, &new);
        let (r, next) = run(state, layout, Op::Commit(&new));
        r.expect("commit");
        state = next;
        old = new;
    }
    tried
}

#[test]
fn power_cut_at_every_step_of_a_commit_leaves_old_or_new_small_flash_byte_writes() {
    let tried = cuts_for_geometry::<256, 1, 1>(1536, SMALL_LAYOUT);
    eprintln!("byte-write flash (ERASE 256, WRITE 1): {tried} cut points");
    assert!(tried > 5 * 4 * 440);
}

#[test]
fn power_cut_at_every_step_of_a_commit_leaves_old_or_new_wide_writes_many_blocks() {
    // 8 erase blocks per slot, 8-byte program words, 4-byte reads.
    let tried = cuts_for_geometry::<64, 8, 4>(1536, SlotLayout::consecutive(512));
    eprintln!("wide-write flash (ERASE 64, WRITE 8, READ 4): {tried} cut points");
    assert!(tried > 0);
}

#[test]
fn power_cut_at_every_step_of_a_commit_leaves_old_or_new_stm32f405_sectors() {
    // The board's geometry: 128 KiB sectors, x32 programming, slots in sectors 10 and 11.
    let layout = SlotLayout::STM32F405_SECTORS_9_11;
    let (t1, t2, t3) = (table(1), table(2), table(3));
    let initial = flash_with::<{ 128 * 1024 }, 4, 1>(1024 * 1024, layout, &[t1, t2]);
    let tried = exhaustive_cuts(&initial, layout, Op::Commit(&t3), &t2, &t3);
    eprintln!("STM32F405 geometry: {tried} cut points");
    assert!(tried > 4 * 110);
}

#[test]
fn power_cut_at_every_step_of_a_prepared_commit_leaves_old_or_new() {
    let (t1, t2, t3) = (table(1), table(2), table(3));
    let initial = flash_with::<256, 1, 1>(1536, SMALL_LAYOUT, &[t1, t2]);
    let tried = exhaustive_cuts(&initial, SMALL_LAYOUT, Op::PreparedCommit(&t3), &t2, &t3);
    eprintln!("prepared commit: {tried} cut points");
    assert!(tried > 0);
}

#[test]
fn prepared_commit_does_not_erase_again() {
    let flash = flash_with::<256, 1, 1>(1536, SMALL_LAYOUT, &[table(1)]);
    let mut s = store(flash, SMALL_LAYOUT);
    assert_eq!(s.prepare_commit(), Ok(Slot::B));
    s.flash.log.clear();
    s.commit(&table(2)).unwrap();
    assert!(!s.flash.log.iter().any(|a| matches!(a, Access::Erase(..))));
    // The next commit was not prepared: it erases its target (C: A holds the rollback table).
    commit_3_erases_slot_c(s);
}

#[test]
fn a_blank_spare_is_not_erased_and_one_with_a_single_programmed_bit_is() {
    let flash = flash_with::<256, 1, 1>(1536, SMALL_LAYOUT, &[table(1)]); // A active
    let mut s = store(flash, SMALL_LAYOUT);
    s.flash.log.clear();
    assert_eq!(s.prepare_commit(), Ok(Slot::B));
    assert!(!s.flash.log.iter().any(|a| matches!(a, Access::Erase(..))));
    assert_eq!(s.erase_count(), 0);
    s.commit(&table(2)).unwrap();
    assert!(!s.flash.log.iter().any(|a| matches!(a, Access::Erase(..))));
    // The last byte of C's marker area with one bit programmed: erased before C is written.
    let marker_end = 1024 + doc_marker_offset(4) + 3;
    s.flash.bytes[marker_end] = 0xFE;
    s.flash.log.clear();
    assert_eq!(s.prepare_commit(), Ok(Slot::C));
    assert!(s.flash.log.contains(&Access::Erase(1024, 1536)));
    assert_eq!(s.erase_count(), 1);
}

#[test]
fn an_erase_that_failed_is_redone_by_the_next_commit() {
    let flash = flash_with::<256, 1, 1>(1536, SMALL_LAYOUT, &[table(1), table(2)]);
    // The erase fails in its second block (a transient driver error: same store, no reboot).
    let mut s = store(flash, SMALL_LAYOUT);
    s.flash.bytes[1024 + 100] = 0x5A; // the spare C is not blank
    s.flash.budget = Some(1);
    assert_eq!(
        s.prepare_commit(),
        Err(StorageError::Flash(SimError::PowerCut))
    );
    s.flash.dead = false;
    s.flash.budget = None;
    assert_eq!(s.spare_erased(), Ok(false));
    commit_3_erases_slot_c(s);
}

#[test]
fn power_cut_at_every_step_of_a_rollback_leaves_current_or_previous() {
    let (t1, t2) = (table(1), table(2));
    let initial = flash_with::<256, 1, 1>(1536, SMALL_LAYOUT, &[t1, t2]);
    let tried = exhaustive_cuts(&initial, SMALL_LAYOUT, Op::Rollback, &t2, &t1);
    eprintln!("rollback: {tried} cut points");
    assert!(tried > 0);
}

#[test]
fn power_cut_at_every_step_across_sequence_wrap_leaves_old_or_new() {
    let (t1, t2) = (table(1), table(2));
    let mut initial = Small::new(1536);
    doc_write_slot(&mut initial.bytes, 0, 4, u32::MAX - 1, &table(7));
    doc_write_slot(&mut initial.bytes, 512, 4, u32::MAX, &t1);
    let tried = exhaustive_cuts(&initial, SMALL_LAYOUT, Op::Commit(&t2), &t1, &t2);
    eprintln!("sequence wrap: {tried} cut points");
    assert!(tried > 0);
    let (r, _) = run(initial, SMALL_LAYOUT, Op::Commit(&t2));
    assert_eq!(
        r,
        Ok(SlotInfo {
            slot: Slot::C,
            sequence: 0,
            table_id: crate::table::table_id(&t2)
        })
    );
}

#[test]
fn repeated_cuts_and_retries_never_lose_the_last_committed_table() {
    // A random walk: commits and rollbacks, each cut at a random step or not at all; the
    // active table after every reboot is the last one known active or the one attempted.
    let tables: Vec<_> = (1..=5).map(table).collect();
    let mut flash = flash_with::<256, 1, 1>(1536, SMALL_LAYOUT, &[tables[0]]);
    let mut active = tables[0];
    let mut rng = Small::new(0).with_budget(0, Cut::RandomBits(42));
    let mut draw = |n: usize| (0..16).fold(0usize, |acc, _| acc * 2 + usize::from(rng.coin())) % n;
    for round in 0..400 {
        let rollback = draw(5) == 0;
        let pick = tables[draw(tables.len())];
        let budget = draw(500); // a commit takes ~450 steps: some rounds finish
        let cut = if draw(2) == 0 {
            Cut::Clean
        } else {
            Cut::RandomBits(round as u64 * 7919 + 1)
        };
        let (_, f) = if rollback {
            run(flash.with_budget(budget, cut), SMALL_LAYOUT, Op::Rollback)
        } else {
            run(
                flash.with_budget(budget, cut),
                SMALL_LAYOUT,
                Op::Commit(&pick),
            )
        };
        let (now, f) = active_after_reboot(f, SMALL_LAYOUT);
        let now = now.unwrap_or_else(|| panic!("no table in round {round}"));
        if !rollback {
            assert!(now == active || now == pick, "round {round}: unknown table");
        }
        active = now;
        flash = f;
    }
}

// ---- refused tables and verification ------------------------------------------------------

#[test]
fn refused_table_touches_nothing() {
    let flash = flash_with::<256, 1, 1>(1536, SMALL_LAYOUT, &[table(1), table(2)]);
    let before = flash.bytes.clone();
    let mut flipped = table(3);
    flipped[100] ^= 0x10;
    let mut nan = paper_table();
    nan.rtd.cvd.r0 = f64::NAN;
    let nan = nan.encode();
    let good = table(3);
    type IsExpected = fn(&StorageError<SimError>) -> bool;
    let cases: [(&[u8], IsExpected); 4] = [
        (&flipped, |e| {
            matches!(e, StorageError::Table(TableError::BadCrc { .. }))
        }),
        (&good[..400], |e| {
            matches!(e, StorageError::Table(TableError::BadLength { .. }))
        }),
        (&nan, |e| {
            matches!(e, StorageError::Table(TableError::NonFinite(_)))
        }),
        (&[0u8; 0], |e| matches!(e, StorageError::Table(_))),
    ];
    let mut s = store(flash, SMALL_LAYOUT);
    s.flash.steps = 0;
    for (bytes, is_expected) in cases {
        let e = s.commit(bytes).expect_err("refused");
        assert!(is_expected(&e), "unexpected error {e:?}");
    }
    let flash = s.into_flash();
    assert_eq!(flash.steps, 0, "no erase or program step");
    assert_eq!(flash.bytes, before);
}

#[test]
fn a_cell_that_will_not_program_fails_verification_and_keeps_the_old_table() {
    let (t1, t2) = (table(1), table(2));
    let mut flash = flash_with::<256, 1, 1>(1536, SMALL_LAYOUT, &[t1]);
    // Slot B (the commit target), inside the table: bit 0 of a byte the table sets to 0.
    let t2_zero = t2.iter().position(|b| b & 1 == 0).unwrap();
    flash.stuck_at_one.push((512 + 16 + t2_zero, 0x01));
    let (r, flash) = run(flash, SMALL_LAYOUT, Op::Commit(&t2));
    assert_eq!(r, Err(StorageError::Verify(Slot::B)));
    let mut s = store(flash, SMALL_LAYOUT);
    assert_eq!(
        s.slot_state(Slot::B).unwrap(),
        SlotState::Invalid(SlotFault::NoCommitMarker)
    );
    let (info, t) = s.load_active().unwrap();
    assert_eq!(info.slot, Slot::A);
    assert_eq!(t.encode(), t1);
}

#[test]
fn a_marker_that_does_not_program_fully_is_caught_after_the_write() {
    let (t1, t2) = (table(1), table(2));
    let mut flash = flash_with::<256, 1, 1>(1536, SMALL_LAYOUT, &[t1]);
    // Marker byte 0 is 0xA5: bit 1 is a zero bit of the marker; make it stick at 1.
    flash.stuck_at_one.push((512 + doc_marker_offset(4), 0x02));
    let (r, flash) = run(flash, SMALL_LAYOUT, Op::Commit(&t2));
    assert_eq!(r, Err(StorageError::Verify(Slot::B)));
    let (active, _) = active_after_reboot(flash, SMALL_LAYOUT);
    assert_eq!(active, Some(t1));
}

// ---- layout, boot and sequence numbers ----------------------------------------------------

#[test]
fn factory_empty_flash_has_no_table() {
    let mut s = store(Small::new(1536), SMALL_LAYOUT);
    assert_eq!(s.active(), None);
    assert_eq!(s.slot_state(Slot::A).unwrap(), SlotState::Blank);
    assert_eq!(s.slot_state(Slot::B).unwrap(), SlotState::Blank);
    assert_eq!(s.slot_state(Slot::C).unwrap(), SlotState::Blank);
    assert!(matches!(s.load_active(), Err(StorageError::NoValidSlot)));
    assert_eq!(s.activate_previous(), Err(StorageError::NoValidSlot));
}

#[test]
fn commits_rotate_through_the_three_slots_with_increasing_sequence_in_the_documented_layout() {
    let mut s = store(SimFlash::<256, 1, 1>::new(1536), SMALL_LAYOUT);
    // Each commit goes to the spare: neither the active nor the rollback slot.
    for (n, (slot, base)) in [(Slot::A, 0), (Slot::B, 512), (Slot::C, 1024), (Slot::A, 0)]
        .into_iter()
        .enumerate()
    {
        let t = table(n as u8 + 1);
        let info = s.commit(&t).unwrap();
        let seq = n as u32 + 1;
        assert_eq!(info.slot, slot);
        assert_eq!(info.sequence, seq);
        assert_eq!(s.active(), Some(info));
        // Compare the raw bytes with an image built from the documentation.
        let mut expected = vec![0xFFu8; 512];
        doc_write_slot(&mut expected, 0, 4, seq, &t);
        assert_eq!(
            &s.flash.bytes[base..base + 512],
            &expected[..],
            "commit {n}"
        );
    }
    assert_eq!(doc_marker_offset(4), 444);
}

#[test]
fn commit_erases_the_inactive_slot_and_programs_the_marker_last_after_read_back() {
    let flash = flash_with::<256, 1, 1>(1536, SMALL_LAYOUT, &[table(1)]); // A active
    let mut s = store(flash, SMALL_LAYOUT);
    s.flash.bytes[512 + 443] = 0x00; // B held an image once
    s.flash.log.clear();
    s.commit(&table(2)).unwrap();
    let changes: Vec<Access> = s
        .flash
        .log
        .iter()
        .copied()
        .filter(|a| !matches!(a, Access::Read(..)))
        .collect();
    let marker = 512 + doc_marker_offset(4) as u32;
    assert_eq!(
        changes,
        [
            Access::Erase(512, 1024),
            Access::Write(512, 444),
            Access::Write(marker, 4),
        ]
    );
    // Between the image write and the marker write, the whole image is read back.
    let log = &s.flash.log;
    let image_at = log
        .iter()
        .position(|a| *a == Access::Write(512, 444))
        .unwrap();
    let marker_at = log
        .iter()
        .position(|a| *a == Access::Write(marker, 4))
        .unwrap();
    assert!(log[image_at..marker_at].contains(&Access::Read(512, 444)));
}

#[test]
fn marker_sits_after_padding_to_the_write_size() {
    let t = table(1);
    let mut s = store(
        SimFlash::<64, 16, 1>::new(1536),
        SlotLayout::consecutive(512),
    );
    s.commit(&t).unwrap();
    let mut expected = vec![0xFFu8; 512];
    doc_write_slot(&mut expected, 0, 16, 1, &t);
    assert_eq!(doc_marker_offset(16), 448);
    assert_eq!(&s.flash.bytes[..512], &expected[..]);
}

#[test]
fn sequence_comparison_survives_wrap_around() {
    assert!(sequence_newer(2, 1));
    assert!(!sequence_newer(1, 2));
    assert!(!sequence_newer(7, 7));
    assert!(sequence_newer(0, 0xFFFF_FFFF));
    assert!(sequence_newer(3, 0xFFFF_FFFE));
    assert!(!sequence_newer(0xFFFF_FFFF, 0));
    assert!(sequence_newer(0x8000_0000, 0x7FFF_FFFF));
}

#[test]
fn boot_picks_the_newest_valid_slot_in_serial_arithmetic() {
    let cases = [
        (5u32, 4u32, Slot::A),
        (4, 5, Slot::B),
        (u32::MAX, 0, Slot::B),
        (0, u32::MAX, Slot::A),
        (0x7FFF_FFFF, 0x8000_0000, Slot::B),
    ];
    for (seq_a, seq_b, winner) in cases {
        let mut f = Small::new(1536);
        doc_write_slot(&mut f.bytes, 0, 4, seq_a, &table(1));
        doc_write_slot(&mut f.bytes, 512, 4, seq_b, &table(2));
        let mut s = store(f, SMALL_LAYOUT);
        let (info, t) = s.load_active().unwrap();
        assert_eq!(info.slot, winner, "seq A {seq_a:#x}, B {seq_b:#x}");
        let expected = if winner == Slot::A {
            table(1)
        } else {
            table(2)
        };
        assert_eq!(t.encode(), expected);
    }
}

#[test]
fn every_partial_program_of_the_marker_is_invalid() {
    // Starting from erased, a cut program clears any subset of the marker's 16 zero bits.
    let zero_bits: Vec<(usize, u8)> = (0..4)
        .flat_map(|i| (0..8).map(move |b| (i, 1u8 << b)))
        .filter(|(i, m)| DOC_MARKER[*i] & m == 0)
        .collect();
    assert_eq!(zero_bits.len(), 16);
    let mut base = Small::new(1536);
    doc_write_slot(&mut base.bytes, 0, 4, 1, &table(1));
    let m = doc_marker_offset(4);
    let mut valid = 0;
    for subset in 0u32..(1 << 16) {
        let mut f = base.clone();
        f.bytes[m..m + 4].fill(0xFF);
        for (j, (i, mask)) in zero_bits.iter().enumerate() {
            if subset & (1 << j) != 0 {
                f.bytes[m + i] &= !mask;
            }
        }
        let state = store(f, SMALL_LAYOUT).slot_state(Slot::A).unwrap();
        if let SlotState::Valid(_) = state {
            valid += 1;
            assert_eq!(subset, 0xFFFF, "partial marker accepted");
        }
    }
    assert_eq!(valid, 1);
}

#[test]
fn a_bit_flip_anywhere_in_one_slot_hands_over_to_the_other() {
    let (t1, t2) = (table(1), table(2));
    let healthy = flash_with::<256, 1, 1>(1536, SMALL_LAYOUT, &[t1, t2]); // A: t1, B: t2 (newer)
    let m = doc_marker_offset(4);
    let covered: Vec<usize> = (0..16 + DOC_TABLE_LEN).chain(m..m + 4).collect();
    let mut flips = 0;
    for (base, survivor) in [(512usize, t1), (0usize, t2)] {
        for &off in &covered {
            for bit in 0..8 {
                let mut f = healthy.clone();
                f.bytes[base + off] ^= 1 << bit;
                let (active, _) = active_after_reboot(f, SMALL_LAYOUT);
                assert_eq!(active, Some(survivor), "flip at slot+{off} bit {bit}");
                flips += 1;
            }
        }
    }
    assert_eq!(flips, 2 * 446 * 8);
    // Both slots corrupted: no table, and the firmware flags NO_CALIBRATION.
    let mut f = healthy;
    f.bytes[16] ^= 1;
    f.bytes[512 + 16] ^= 1;
    let (active, _) = active_after_reboot(f, SMALL_LAYOUT);
    assert_eq!(active, None);
}

#[test]
fn slot_faults_are_named() {
    let t = table(1);
    let m = doc_marker_offset(4);
    let fault = |edit: &dyn Fn(&mut Vec<u8>)| {
        let mut f = Small::new(1536);
        doc_write_slot(&mut f.bytes, 0, 4, 1, &t);
        edit(&mut f.bytes);
        store(f, SMALL_LAYOUT).slot_state(Slot::A).unwrap()
    };
    assert_eq!(
        fault(&|b| b[0] = b'X'),
        SlotState::Invalid(SlotFault::BadMagic)
    );
    assert_eq!(
        fault(&|b| b[8] = 0x00),
        SlotState::Invalid(SlotFault::BadLength(0x100))
    );
    assert_eq!(
        fault(&|b| b[m] = 0xFF),
        SlotState::Invalid(SlotFault::NoCommitMarker)
    );
    assert_eq!(
        fault(&|b| b[4] ^= 0x01),
        SlotState::Invalid(SlotFault::BadCrc)
    );
    // A table with a bad inner value but a matching slot CRC: the table validator decides.
    let mut nan = paper_table();
    nan.rtd.cvd.r0 = f64::NAN;
    let mut f = Small::new(1536);
    doc_write_slot(&mut f.bytes, 0, 4, 1, &nan.encode());
    assert!(matches!(
        store(f, SMALL_LAYOUT).slot_state(Slot::A).unwrap(),
        SlotState::Invalid(SlotFault::Table(TableError::NonFinite(_)))
    ));
}

// ---- rollback -----------------------------------------------------------------------------

#[test]
fn rollback_recommits_the_previous_table_into_the_spare_and_keeps_the_other_for_rollback() {
    let (t1, t2) = (table(1), table(2));
    let flash = flash_with::<256, 1, 1>(1536, SMALL_LAYOUT, &[t1, t2]); // A: t1, B: t2
    let mut s = store(flash, SMALL_LAYOUT);
    s.flash.log.clear();
    let info = s.activate_previous().unwrap();
    assert_eq!(info.slot, Slot::C, "written into the spare");
    assert_eq!(info.sequence, 3);
    assert!(
        !s.flash
            .log
            .iter()
            .any(|a| matches!(a, Access::Erase(o, _) | Access::Write(o, _) if *o < 1024)),
        "the active and the rollback slot are never written"
    );
    // After a reboot: t1 active, t2 the rollback table; a second rollback returns to t2.
    let mut s = store(s.into_flash().reboot(), SMALL_LAYOUT);
    assert_eq!(s.load_active().unwrap().1.encode(), t1);
    let v = s.valid_slots().unwrap();
    assert_eq!(v.previous.map(|p| p.slot), Some(Slot::B));
    let info = s.activate_previous().unwrap();
    assert_eq!(info.slot, Slot::A, "the stale copy of t1 is the spare now");
    let mut s = store(s.into_flash().reboot(), SMALL_LAYOUT);
    assert_eq!(s.load_active().unwrap().1.encode(), t2);
    assert_eq!(
        s.valid_slots().unwrap().previous.map(|p| p.slot),
        Some(Slot::C)
    );
}

#[test]
fn the_spare_erased_ahead_is_the_next_target_and_is_not_erased_again() {
    let (t1, t2, t3) = (table(1), table(2), table(3));
    let flash = flash_with::<256, 1, 1>(1536, SMALL_LAYOUT, &[t1, t2, t3]); // A t1, B t2, C t3
    let mut s = store(flash, SMALL_LAYOUT);
    assert_eq!(s.spare_erased(), Ok(false));
    assert_eq!(
        s.prepare_commit(),
        Ok(Slot::A),
        "t1 is neither active nor previous"
    );
    assert_eq!(s.spare_erased(), Ok(true));
    s.flash.log.clear();
    assert_eq!(s.prepare_commit(), Ok(Slot::A));
    assert!(
        s.flash.log.iter().all(|a| matches!(a, Access::Read(..))),
        "no second erase"
    );
    // Erased ahead: still t3 active and t2 previous after a reboot.
    let mut s = store(s.into_flash().reboot(), SMALL_LAYOUT);
    let v = s.valid_slots().unwrap();
    assert_eq!(
        (v.newest.map(|i| i.slot), v.previous.map(|i| i.slot)),
        (Some(Slot::C), Some(Slot::B))
    );
    assert_eq!(s.slot_state(Slot::A), Ok(SlotState::Blank));
}

#[test]
fn rollback_without_a_previous_table_is_refused() {
    let flash = flash_with::<256, 1, 1>(1536, SMALL_LAYOUT, &[table(1)]);
    let mut s = store(flash, SMALL_LAYOUT);
    assert_eq!(s.activate_previous(), Err(StorageError::NoPreviousSlot));
}

// ---- geometry -----------------------------------------------------------------------------

#[test]
fn layouts_that_do_not_fit_the_flash_are_refused() {
    let cases = [
        (SlotLayout::consecutive(384), LayoutError::NotEraseAligned),
        (SlotLayout::consecutive(0), LayoutError::NotEraseAligned),
        (SlotLayout::consecutive(256), LayoutError::SlotTooSmall),
        (
            SlotLayout {
                slot_offsets: [0, 1024, 256],
                slot_len: 512,
            },
            LayoutError::Overlap,
        ),
        (SlotLayout::consecutive(1024), LayoutError::OutOfBounds),
        (
            SlotLayout {
                slot_offsets: [0, 512, 1536],
                slot_len: 512,
            },
            LayoutError::OutOfBounds,
        ),
    ];
    for (layout, expected) in cases {
        assert!(
            matches!(
                CalibrationStore::new(Small::new(1536), layout),
                Err(StorageError::Layout(e)) if e == expected
            ),
            "{layout:?}"
        );
    }
    assert!(matches!(
        CalibrationStore::new(SimFlash::<256, 128, 1>::new(1536), SMALL_LAYOUT),
        Err(StorageError::Layout(LayoutError::AlignmentTooLarge))
    ));
}

#[test]
fn stm32f405_layout_fits_a_one_mebibyte_flash_with_128k_sectors() {
    let f = SimFlash::<{ 128 * 1024 }, 4, 1>::new(1024 * 1024);
    let mut s = CalibrationStore::new(f, SlotLayout::STM32F405_SECTORS_9_11).unwrap();
    s.commit(&table(1)).unwrap();
    let bytes = &s.flash.bytes;
    assert_eq!(&bytes[0xA_0000..0xA_0004], DOC_MAGIC);
    assert!(
        bytes[..0xA_0000].iter().all(|b| *b == 0xFF),
        "program area untouched"
    );
}

#[test]
fn ram_flash_holds_tables_for_the_qemu_board() {
    let mut s = CalibrationStore::new(
        RamFlash::<3072, 1024, 4>::new(),
        SlotLayout::consecutive(1024),
    )
    .unwrap();
    assert_eq!(s.active(), None);
    s.commit(&table(1)).unwrap();
    s.commit(&table(2)).unwrap();
    let f = s.into_flash();
    let mut s = CalibrationStore::new(
        RamFlash::<3072, 1024, 4>::from_bytes(*f.as_bytes()),
        SlotLayout::consecutive(1024),
    )
    .unwrap();
    assert_eq!(s.load_active().unwrap().1.encode(), table(2));
    assert_eq!(s.activate_previous().unwrap().sequence, 3);
    assert_eq!(s.load_active().unwrap().1.encode(), table(1));
}
