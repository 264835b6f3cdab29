//! Firmware entry point for the STM32F405 compensation front-end (RTIC 2).
//!
//! Thin on purpose: the board support package (`bsp`) sets up clocks, UART, acquisition and the watchdog; the
//! core's [`accomp::acquisition`] sequences the converters and [`accomp::service::Service`]
//! answers requests and runs the per-sample pipeline. This file only moves bytes, readings and
//! samples between them, at these priorities:
//!
//! | priority | task | may do |
//! |---|---|---|
//! | 3 | `drdy` (EXTI1) | timestamp, read one conversion, switch the mux: bounded SPI, no wait |
//! | 2 | `uart_rx` (USART1) | drain the received bytes (front-end: the DMA ring) into the frame decoder |
//! | 2 | `ads_supervisor`, `rtd_task` | one tick of a sequencer each: bounded SPI, no wait |
//! | 1 | `worker`, `watchdog` | pipeline, protocol, flash; progress checks and IWDG feeding |
//!
//! On the host this file compiles to an empty program so that `cargo test` at the root can build
//! the workspace; the firmware exists only for `target_os = "none"`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(all(target_os = "none", feature = "board-qemu", feature = "board-frontend"))]
compile_error!("choose exactly one board: `board-qemu` (default) or `board-frontend`");

// The per-board glue (board support package: HAL types, clocks, interrupts). The board's
// description — pins, buses, channel map, driver configurations — is the core's
// `accomp::board`, which the host shares; the glue builds the hardware from it.
#[cfg(target_os = "none")]
mod bsp;

// 1 kHz ticks for the tasks' delays (time stamps come from TIM2): faster ticks starved QEMU's
// UART (tried 20 kHz and 100 kHz: requests went unanswered).
#[cfg(target_os = "none")]
rtic_monotonics::systick_monotonic!(Mono, 1_000);

#[cfg(target_os = "none")]
#[rtic::app(device = stm32f4xx_hal::pac, peripherals = true, dispatchers = [SPI3, UART4])]
mod app {
    use core::sync::atomic::{AtomicU32, Ordering};

    use accomp::acquisition::{AdsReading, RtdReading, SampleAssembler};
    use accomp::drivers::ads1262::DataRate;
    use accomp::pipeline::LossFlags;
    use accomp::protocol::{
        encode_frame, DeviceMessage, FrameDecoder, FrameError, MAX_FRAME_LEN, PROTOCOL_VERSION,
    };
    use accomp::service::{BootTable, Service};
    use accomp::timebase::{drdy_edge_time, Extended64, StampSource};
    use heapless::Vec;
    use rtic_monotonics::fugit::ExtU64 as _;
    use rtic_monotonics::Timebase as _;
    use rtic_sync::channel::{Receiver, Sender};
    use rtic_sync::make_channel;

    use crate::bsp;
    use crate::Mono;

    /// Frames, readings and heartbeats waiting for the worker. Bounded: when full, frames are
    /// dropped and counted (the host sees the count in Info and resends), readings are lost
    /// (the frame sequence shows the gap), never queued without limit.
    const INBOUND_CAPACITY: usize = 16;

    /// How often the ADS1262 supervisor checks for a missing DRDY (and drives re-init steps).
    const ADS_TICK_MS: u64 = 20;
    /// How often the watchdog task checks progress (the IWDG itself allows ≥ 10.9 s).
    const WATCHDOG_CHECK_MS: u64 = 1_000;
    /// An RTD reading further than this from a pair's timestamp is not joined to it.
    const RTD_MAX_AGE_US: u64 = 1_000_000;

    /// Work for the worker, in arrival order.
    pub enum Inbound {
        /// A received frame body, or why the receiver refused it.
        Frame(Result<Vec<u8, MAX_FRAME_LEN>, FrameError>),
        /// An accelerometer + tilt pair (or a timeout reading) from the ADS1262 sequencer.
        Ads(AdsReading),
        /// An RTD reading from the AD7124 task.
        Rtd(RtdReading),
        /// Proof of life requested by the watchdog task.
        Heartbeat,
    }

    /// Frames lost because the inbound queue was full (added to the service's counter).
    static QUEUE_DROPS: AtomicU32 = AtomicU32::new(0);
    /// Readings lost because the inbound queue was full — accelerometer pairs, whose seq
    /// numbers are the gap, and RTD readings (the next pairs join the previous RTD reading, at
    /// most `RTD_MAX_AGE_US` old): the next pair says QUEUE_FULL, Info's `queue_full` counts
    /// them.
    static READINGS_DROPPED: AtomicU32 = AtomicU32::new(0);
    /// Readings produced by the ADS1262 sequencer (DRDY or timeout): acquisition progress.
    static ACQ_PROGRESS: AtomicU32 = AtomicU32::new(0);
    /// Items the worker has processed: worker progress.
    static WORKER_PROGRESS: AtomicU32 = AtomicU32::new(0);
    /// DRDY readings stamped with the handler's read of the time base because no capture of
    /// the edge was pending (front-end: CC2IF clear): late by the interrupt latency.
    static DRDY_HANDLER_STAMPS: AtomicU32 = AtomicU32::new(0);
    /// Data rate asked for by SetRate, for the supervisor to apply (0: nothing new).
    static REQUESTED_RATE: AtomicU32 = AtomicU32::new(0);

    #[shared]
    struct Shared {
        /// Read by the DRDY interrupt (priority 3) and the supervisor (priority 2, short locks:
        /// a few SPI transactions, never a wait).
        ads: bsp::AdsAcquisition,
    }

    #[local]
    struct Local {
        rx: bsp::UartRx,
        tx: bsp::UartTx,
        decoder: FrameDecoder<MAX_FRAME_LEN>,
        rx_to_worker: Sender<'static, Inbound, INBOUND_CAPACITY>,
        drdy_pin: bsp::DrdyPin,
        drdy_to_worker: Sender<'static, Inbound, INBOUND_CAPACITY>,
        supervisor_to_worker: Sender<'static, Inbound, INBOUND_CAPACITY>,
        rtd: bsp::RtdAcquisition,
        rtd_to_worker: Sender<'static, Inbound, INBOUND_CAPACITY>,
        watchdog: bsp::Watchdog,
        watchdog_to_worker: Sender<'static, Inbound, INBOUND_CAPACITY>,
        service: Service<bsp::Flash>,
        assembler: SampleAssembler,
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        let parts = bsp::init(cx.device);
        Mono::start(cx.core.SYST, bsp::SYSTICK_HZ);
        // Boot restores the newest valid calibration slot (none: samples flag NO_CALIBRATION).
        let mut service = Service::new(bsp::BOARD, parts.flash, bsp::SLOT_LAYOUT);
        let kept = bsp::keep_across_resets(parts.boot);
        let boot = accomp::protocol::BootReport {
            boot_id: kept.boot_id,
            ..parts.boot
        };
        service.set_boot_report(boot);
        service.losses_mut().watchdog_resets = kept.watchdog_resets;
        service.losses_mut().brownout_resets = kept.brownout_resets;
        defmt::info!(
            "reset cause {=u8:#x}, clock fallback {}, boot id {=u32:#x}",
            boot.reset_cause,
            boot.clock_fallback,
            boot.boot_id
        );
        match service.boot_table() {
            BootTable::Restored {
                sequence,
                with_previous,
            } => defmt::info!(
                "calibration restored from slot sequence {} (rollback table: {})",
                sequence,
                with_previous
            ),
            BootTable::Empty => defmt::warn!("no valid calibration slot: NO_CALIBRATION"),
            BootTable::StorageFault => defmt::error!("calibration store unreadable"),
        }
        let (rx_to_worker, inbound) = make_channel!(Inbound, INBOUND_CAPACITY);
        if worker::spawn(inbound).is_err() || watchdog::spawn().is_err() {
            bsp::fatal(bsp::Fatal::Spawn);
        }
        if bsp::HAS_ADCS && (ads_supervisor::spawn().is_err() || rtd_task::spawn().is_err()) {
            bsp::fatal(bsp::Fatal::Spawn);
        }
        defmt::info!("accomp-fw {} up", env!("CARGO_PKG_VERSION"));
        (
            Shared { ads: parts.ads },
            Local {
                rx: parts.rx,
                tx: parts.tx,
                decoder: FrameDecoder::new(),
                drdy_pin: parts.drdy,
                drdy_to_worker: rx_to_worker.clone(),
                supervisor_to_worker: rx_to_worker.clone(),
                rtd: parts.rtd,
                rtd_to_worker: rx_to_worker.clone(),
                watchdog: parts.watchdog,
                watchdog_to_worker: rx_to_worker.clone(),
                rx_to_worker,
                service,
                assembler: SampleAssembler::new(RTD_MAX_AGE_US),
            },
        )
    }

    /// Drains the UART receiver into the frame decoder; complete frames go to the worker.
    #[task(binds = USART1, priority = 2, local = [rx, decoder, rx_to_worker])]
    fn uart_rx(cx: uart_rx::Context) {
        while let Some(byte) = bsp::read_byte(cx.local.rx) {
            if let Some(frame) = cx.local.decoder.push(byte) {
                let item = Inbound::Frame(
                    frame.and_then(|body| Vec::from_slice(body).map_err(|_| FrameError::TooLong)),
                );
                if cx.local.rx_to_worker.try_send(item).is_err() {
                    QUEUE_DROPS.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }

    /// ADS1262 DRDY fell: timestamp it, read the conversion and switch the mux (a few SPI
    /// transactions at 5.25 MHz, no waiting), hand a finished pair to the worker. The QEMU board
    /// never enables EXTI1.
    ///
    /// The stamp is the edge's: the count the time base latched at the DRDY edge (front-end:
    /// TIM2_CH2 input capture), read before the counter itself so that it is never the newer of
    /// the two. Without a pending capture the handler's read stands in, later by the interrupt
    /// latency; such readings are counted and logged by the watchdog task.
    #[task(binds = EXTI1, priority = 3, shared = [ads], local = [drdy_pin, drdy_to_worker])]
    fn drdy(mut cx: drdy::Context) {
        let captured = bsp::drdy_capture();
        let read = now_us();
        // The extended time's low 32 bits are the counter's count at that read.
        let (now, source) = drdy_edge_time(read, read as u32, captured);
        if source == StampSource::HandlerRead {
            DRDY_HANDLER_STAMPS.fetch_add(1, Ordering::Relaxed);
        }
        bsp::acknowledge_drdy(cx.local.drdy_pin);
        ACQ_PROGRESS.fetch_add(1, Ordering::Relaxed);
        // Served after a flash stall: the pair's other half was converted before the stall, and
        // where no edge was captured (the QEMU board) the conversion's time is unknown. The pair
        // starts again; the pairs lost are the next frame's seq gap, flagged STALL and counted.
        let stalled = accomp::drivers::stm32f4_flash::OPERATION.load(Ordering::Relaxed);
        if let Some(reading) = cx.shared.ads.lock(|ads| {
            if stalled {
                ads.restart_pair();
            }
            ads.on_drdy(now)
        }) {
            // A full queue loses this reading: counted, and flagged on the next one.
            if cx
                .local
                .drdy_to_worker
                .try_send(Inbound::Ads(reading))
                .is_err()
            {
                READINGS_DROPPED.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Watches for a missing DRDY (timeout readings at the pair rate, stepped re-init) and
    /// applies SetRate. Same priority as the UART receiver, never above it, and never waits.
    #[task(priority = 2, shared = [ads], local = [supervisor_to_worker])]
    async fn ads_supervisor(mut cx: ads_supervisor::Context) {
        loop {
            Mono::delay(ADS_TICK_MS.millis()).await;
            // The front-end's UART bytes arrive by DMA: wake the reader at least every tick, in
            // case a byte's RXNE interrupt ran before the DMA had moved it into the ring.
            rtic::pend(stm32f4xx_hal::pac::Interrupt::USART1);
            let now = now_us();
            let rate = DataRate::from_sps(REQUESTED_RATE.swap(0, Ordering::Relaxed));
            let reading = cx.shared.ads.lock(|ads| {
                if let Some(rate) = rate {
                    ads.request_rate(rate);
                }
                ads.on_tick(now)
            });
            if let Some(reading) = reading {
                ACQ_PROGRESS.fetch_add(1, Ordering::Relaxed);
                if cx
                    .local
                    .supervisor_to_worker
                    .try_send(Inbound::Ads(reading))
                    .is_err()
                {
                    READINGS_DROPPED.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }

    /// Reads the AD7124 at its own data rate: one STATUS poll per tick, the result if ready.
    #[task(priority = 2, local = [rtd, rtd_to_worker])]
    async fn rtd_task(cx: rtd_task::Context) {
        let period_us = cx.local.rtd.period_us();
        loop {
            Mono::delay(period_us.micros()).await;
            if let Some(reading) = cx.local.rtd.on_tick(now_us()) {
                if cx
                    .local
                    .rtd_to_worker
                    .try_send(Inbound::Rtd(reading))
                    .is_err()
                {
                    READINGS_DROPPED.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }

    /// Feeds the independent watchdog only when, since the last check, acquisition produced a
    /// reading (front-end) and the worker processed something (an idle worker gets a heartbeat
    /// to answer, so it feeds every other second). A stuck worker, a dead supervisor or a
    /// lock-up stops the feeding and the IWDG (16 s nominal) resets the MCU.
    #[task(priority = 1, local = [watchdog, watchdog_to_worker])]
    async fn watchdog(cx: watchdog::Context) {
        let mut acquisition = ACQ_PROGRESS.load(Ordering::Relaxed);
        let mut worker = WORKER_PROGRESS.load(Ordering::Relaxed);
        let mut heartbeat_sent = false;
        let mut handler_stamps = 0;
        loop {
            Mono::delay(WATCHDOG_CHECK_MS.millis()).await;
            // Reads the time base at least once per second on both boards, far more often than
            // the 71.6 min its 32-bit count takes to wrap (the extension needs one read a wrap).
            let _ = now_us();
            let stamps = DRDY_HANDLER_STAMPS.load(Ordering::Relaxed);
            if stamps != handler_stamps {
                defmt::warn!(
                    "{} DRDY readings stamped by the handler (no edge capture)",
                    stamps.wrapping_sub(handler_stamps)
                );
                handler_stamps = stamps;
            }
            let a = ACQ_PROGRESS.load(Ordering::Relaxed);
            let w = WORKER_PROGRESS.load(Ordering::Relaxed);
            let acquisition_alive = !bsp::HAS_ADCS || a != acquisition;
            let worker_alive = w != worker;
            if acquisition_alive && worker_alive {
                cx.local.watchdog.feed();
            } else if !acquisition_alive || heartbeat_sent {
                defmt::warn!(
                    "no progress (acquisition {}, worker {}): watchdog not fed",
                    acquisition_alive,
                    worker_alive
                );
            }
            // An idle worker proves itself by answering a heartbeat before the next check (a
            // busy one needs none: nothing extra in its queue while it streams).
            heartbeat_sent = !worker_alive
                && cx
                    .local
                    .watchdog_to_worker
                    .try_send(Inbound::Heartbeat)
                    .is_ok();
            acquisition = a;
            worker = w;
        }
    }

    /// Answers requests and runs samples through the pipeline, one at a time, in order.
    #[task(priority = 1, local = [tx, service, assembler])]
    async fn worker(
        cx: worker::Context,
        mut inbound: Receiver<'static, Inbound, INBOUND_CAPACITY>,
    ) {
        let ready = DeviceMessage::Ready {
            board: bsp::BOARD,
            protocol: PROTOCOL_VERSION,
        };
        send(cx.local.tx, &ready);
        let mut rate_hz = cx.local.service.rate_hz();
        while let Ok(item) = inbound.recv().await {
            WORKER_PROGRESS.fetch_add(1, Ordering::Relaxed);
            let service = &mut *cx.local.service;
            for _ in 0..QUEUE_DROPS.swap(0, Ordering::Relaxed) {
                service.count_dropped();
            }
            if bsp::clock_failed() {
                service.clock_fell_back();
            }
            let losses = service.losses_mut();
            losses.uart_rx_overrun = bsp::UART_OVERRUNS.load(Ordering::Relaxed);
            losses.uart_framing_noise = bsp::UART_LINE_ERRORS.load(Ordering::Relaxed);
            let reply = match item {
                Inbound::Frame(frame) => {
                    service.handle_frame(frame.as_deref().map_err(|e| *e), &now_us)
                }
                Inbound::Ads(reading) => {
                    let mut lost = reading.lost;
                    let dropped = READINGS_DROPPED.swap(0, Ordering::Relaxed);
                    if dropped > 0 {
                        lost.0 |= LossFlags::QUEUE_FULL;
                        let losses = service.losses_mut();
                        losses.queue_full = losses.queue_full.wrapping_add(dropped);
                    }
                    let raw = cx.local.assembler.assemble(&reading);
                    // Timestamped at the DRDY edge, not now.
                    service.acquired(reading.seq, lost, &raw, reading.time_us)
                }
                Inbound::Rtd(reading) => {
                    cx.local.assembler.rtd(reading);
                    None
                }
                Inbound::Heartbeat => None,
            };
            if service.rate_hz() != rate_hz {
                rate_hz = service.rate_hz();
                REQUESTED_RATE.store(rate_hz, Ordering::Relaxed);
            }
            if let Some(msg) = reply {
                send(cx.local.tx, &msg);
            }
            // Erase ahead the slot the next upload will write, after the answer is out, only
            // when no request is waiting and never while streaming (the service refuses then).
            // On the STM32F405 this stalls the CPU for the sector erase (single bank, RM0090
            // §3.5; docs/storage.md); a spare that reads blank is not erased.
            if service.erase_pending() && inbound.is_empty() {
                match service.erase_ahead(&now_us) {
                    Ok(true) => defmt::info!("spare calibration slot erased ahead"),
                    Ok(false) => {}
                    Err(e) => defmt::warn!("erase ahead failed: code {}", e.code),
                }
            }
        }
    }

    /// The board's hardware time base extended to 64 bits. A `Cell`, not a `RefCell`: the
    /// extension is copied out and back inside the critical section, so there is no borrow
    /// that could fail (a `RefCell`'s "already borrowed" panic would bring `core::fmt` along).
    static TIME_BASE: cortex_m::interrupt::Mutex<core::cell::Cell<Extended64>> =
        cortex_m::interrupt::Mutex::new(core::cell::Cell::new(Extended64::new()));

    /// Firmware time in µs: the board's TIM2 at 1 MHz extended to 64 bits (both boards; on the
    /// front-end it counts on through a flash-erase stall). A few instructions with interrupts
    /// masked, so that the count and the extension agree.
    fn now_us() -> u64 {
        cortex_m::interrupt::free(|cs| {
            let cell = TIME_BASE.borrow(cs);
            let mut time = cell.get();
            let us = time.extend(bsp::time_base_count());
            cell.set(time);
            us
        })
    }

    fn send(tx: &mut bsp::UartTx, msg: &DeviceMessage) {
        let mut out = [0u8; MAX_FRAME_LEN];
        match encode_frame(msg, &mut out) {
            Ok(n) => bsp::write_all(tx, out.get(..n).unwrap_or(&[])),
            // Every message is sized to fit (tested in the core); this is a bug, log it.
            Err(_) => defmt::error!("frame too long to send"),
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("accomp-fw is firmware: build it with `cargo build --release --target thumbv7em-none-eabihf`");
}
