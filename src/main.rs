//! Firmware entry point for the STM32F405 compensation front-end (RTIC 2).
//!
//! Thin on purpose: the board module sets up clocks, UART and acquisition; the core's
//! [`accomp::service::Service`] answers requests and runs the per-sample pipeline. This file only
//! moves bytes and samples between them.
//!
//! On the host this file compiles to an empty program so that `cargo test` at the root can build
//! the workspace; the firmware exists only for `target_os = "none"`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(all(target_os = "none", feature = "board-qemu", feature = "board-frontend"))]
compile_error!("choose exactly one board: `board-qemu` (default) or `board-frontend`");

#[cfg(target_os = "none")]
mod board;

// 1 kHz ticks: ms timestamps suffice, and faster ticks starved QEMU's UART (tried 20 kHz and
// 100 kHz: requests went unanswered).
#[cfg(target_os = "none")]
rtic_monotonics::systick_monotonic!(Mono, 1_000);

#[cfg(target_os = "none")]
#[rtic::app(device = stm32f4xx_hal::pac, peripherals = true, dispatchers = [SPI2, SPI3])]
mod app {
    use core::sync::atomic::{AtomicU32, Ordering};

    use accomp::pipeline::RawSample;
    use accomp::protocol::{
        encode_frame, DeviceMessage, FrameDecoder, FrameError, MAX_FRAME_LEN, PROTOCOL_VERSION,
    };
    use accomp::service::{BootTable, Service};
    use heapless::Vec;
    use rtic_monotonics::Timebase as _;
    use rtic_sync::channel::{Receiver, Sender};
    use rtic_sync::make_channel;

    use crate::board;
    use crate::Mono;

    /// Frames and samples waiting for the worker. Bounded: when full, frames are dropped and
    /// counted (the host sees the count in Info and resends), never queued without limit.
    const INBOUND_CAPACITY: usize = 16;

    /// A received frame body, or why the receiver refused it; or an acquired sample.
    pub enum Inbound {
        Frame(Result<Vec<u8, MAX_FRAME_LEN>, FrameError>),
        Sample(RawSample),
    }

    /// Frames lost because the inbound queue was full (added to the service's counter).
    static QUEUE_DROPS: AtomicU32 = AtomicU32::new(0);

    #[shared]
    struct Shared {}

    #[local]
    struct Local {
        rx: board::UartRx,
        tx: board::UartTx,
        decoder: FrameDecoder<MAX_FRAME_LEN>,
        rx_to_worker: Sender<'static, Inbound, INBOUND_CAPACITY>,
        acquisition: board::Acquisition,
        acq_to_worker: Sender<'static, Inbound, INBOUND_CAPACITY>,
        service: Service<board::Flash>,
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        let parts = board::init(cx.device);
        Mono::start(cx.core.SYST, board::SYSTICK_HZ);
        // Boot restores the newest valid calibration slot (none: samples flag NO_CALIBRATION).
        let service = Service::new(board::BOARD, parts.flash, board::SLOT_LAYOUT);
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
        if worker::spawn(inbound).is_err() {
            board::fatal(board::Fatal::Spawn);
        }
        defmt::info!("accomp-fw {} up", env!("CARGO_PKG_VERSION"));
        (
            Shared {},
            Local {
                rx: parts.rx,
                tx: parts.tx,
                decoder: FrameDecoder::new(),
                acquisition: parts.acquisition,
                acq_to_worker: rx_to_worker.clone(),
                rx_to_worker,
                service,
            },
        )
    }

    /// Drains the UART receiver into the frame decoder; complete frames go to the worker.
    #[task(binds = USART1, priority = 2, local = [rx, decoder, rx_to_worker])]
    fn uart_rx(cx: uart_rx::Context) {
        while let Some(byte) = board::read_byte(cx.local.rx) {
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

    /// One conversion set per DRDY edge of the ADS1262 (the QEMU board never enables EXTI4).
    #[task(binds = EXTI4, priority = 3, local = [acquisition, acq_to_worker])]
    fn drdy(cx: drdy::Context) {
        if let Some(raw) = cx.local.acquisition.on_drdy() {
            // A full queue loses this sample; the frame's seq gap shows it on the host.
            let _ = cx.local.acq_to_worker.try_send(Inbound::Sample(raw));
        }
    }

    /// Answers requests and runs samples through the pipeline, one at a time, in order.
    #[task(priority = 1, local = [tx, service])]
    async fn worker(
        cx: worker::Context,
        mut inbound: Receiver<'static, Inbound, INBOUND_CAPACITY>,
    ) {
        let ready = DeviceMessage::Ready {
            board: board::BOARD,
            protocol: PROTOCOL_VERSION,
        };
        send(cx.local.tx, &ready);
        while let Ok(item) = inbound.recv().await {
            let service = &mut *cx.local.service;
            for _ in 0..QUEUE_DROPS.swap(0, Ordering::Relaxed) {
                service.count_dropped();
            }
            let reply = match item {
                Inbound::Frame(frame) => {
                    service.handle_frame(frame.as_deref().map_err(|e| *e), &now_us)
                }
                Inbound::Sample(raw) => service
                    .streaming()
                    .then(|| service.sample(0, &raw, now_us())),
            };
            if let Some(msg) = reply {
                send(cx.local.tx, &msg);
            }
            // Erase ahead the slot the next upload will write, after the answer is out and
            // only when no request is waiting. On the STM32F405 this stalls the CPU for the
            // sector erase (single bank, RM0090 §3.5; docs/storage.md): it happens right after
            // a change of table or at boot, never during an upload.
            if service.erase_pending() && inbound.is_empty() {
                match service.erase_ahead() {
                    Ok(true) => defmt::info!("spare calibration slot erased ahead"),
                    Ok(false) => {}
                    Err(e) => defmt::warn!("erase ahead failed: code {}", e.code),
                }
            }
        }
    }

    /// Firmware time in µs, at the resolution of the board's tick (64-bit ticks never wrap).
    fn now_us() -> u64 {
        Mono::now().duration_since_epoch().as_micros()
    }

    fn send(tx: &mut board::UartTx, msg: &DeviceMessage) {
        let mut out = [0u8; MAX_FRAME_LEN];
        match encode_frame(msg, &mut out) {
            Ok(n) => board::write_all(tx, out.get(..n).unwrap_or(&[])),
            // Every message is sized to fit (tested in the core); this is a bug, log it.
            Err(_) => defmt::error!("frame too long to send"),
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("accomp-fw is firmware: build it with `cargo build --release --target thumbv7em-none-eabihf`");
}
