//! Firmware entry point for the STM32F405 compensation front-end.
//!
//! On the host this file compiles to an empty program so that `cargo test` at the root can build
//! the workspace; the firmware exists only for `target_os = "none"`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod firmware {
    use cortex_m_rt::entry;

    #[entry]
    fn main() -> ! {
        // Foundation stage: boot and idle. Acquisition and the UART protocol come with the
        // RTIC application (src/board/).
        loop {
            cortex_m::asm::wfi();
        }
    }

    #[panic_handler]
    fn panic(_info: &core::panic::PanicInfo) -> ! {
        cortex_m::interrupt::disable();
        loop {
            cortex_m::asm::bkpt();
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("accomp-fw is firmware: build it with `cargo build --release --target thumbv7em-none-eabihf`");
}
