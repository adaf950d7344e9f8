//! microslam on a Cortex-M4F: the board-agnostic main loop and the board support.
//!
//! - [`serve`]: frames in → [`Session`] (core) → estimate frames out, over any
//!   `embedded_io` serial port and an `embedded_hal` output pin for a heartbeat LED.
//! - [`board`]: the board behind a feature: `qemu` (mps2-an386, the default) or
//!   `stm32f411`.
//! - [`stack`]: the stack high-water mark (cortex-m-rt `paint-stack`).
//! - [`config`]: the estimator settings, shared with the host reference.
//! - `flash` (QEMU): a NOR flash stand-in in QEMU's SRAM for the keyframe store.
#![no_std]

#[cfg(all(feature = "qemu", feature = "stm32f411"))]
compile_error!(
    "choose one board: feature `qemu` (default) or `stm32f411` with --no-default-features"
);
#[cfg(not(any(feature = "qemu", feature = "stm32f411")))]
compile_error!("choose a board: feature `qemu` or `stm32f411`");

pub mod board;
pub mod config;
#[cfg(feature = "qemu")]
pub mod cost;
#[cfg(feature = "qemu")]
pub mod flash;
pub mod kept_pose;
pub mod nb_io;
pub mod stack;

use embedded_hal::digital::OutputPin;
use embedded_io::{Read, Write};
use microslam::device::Session;
use microslam::wire::{MAX_FRAME_LEN, ToHost, encode_frame};

/// Defines the binary's `HardFault` handler: log the faulting address (defmt) and halt
/// with code 3 ([`board::halt`]). One handler for every binary of this package; each
/// invokes the macro once at its top level.
#[macro_export]
macro_rules! hard_fault_halts {
    () => {
        #[cortex_m_rt::exception]
        unsafe fn HardFault(frame: &cortex_m_rt::ExceptionFrame) -> ! {
            defmt::error!("HardFault at pc = {:#010x}", frame.pc());
            $crate::board::halt(3)
        }
    };
}

/// Events between two toggles of the heartbeat LED.
pub const HEARTBEAT_EVENTS: u32 = 64;

/// Runs the device forever: reads bytes from `serial`, feeds them to `session`, writes
/// every reply as one frame, toggles `led` every [`HEARTBEAT_EVENTS`] replies. Status
/// replies carry the stack high-water mark from `stack_peak_bytes`. Every reply is shown
/// to `after_reply` once it is written, with whether the device resets next (the firmware
/// keeps the robot's pose in flash there). After the reply to a `Restart` command the
/// processor is reset (SYSRESETREQ), as by the board's reset button.
///
/// Nothing waits for the host: replies are written as soon as a frame is complete, and
/// the host streams frames without waiting for them.
pub fn serve<S, L, const N: usize, const P: usize, const IDS: usize>(
    session: &mut Session<'_, N, P, IDS>,
    serial: &mut S,
    led: &mut L,
    stack_peak_bytes: impl Fn() -> u32,
    mut after_reply: impl FnMut(&ToHost, bool),
) -> !
where
    S: Read + Write,
    L: OutputPin,
{
    let mut rx = [0u8; 64];
    let mut tx = [0u8; MAX_FRAME_LEN];
    let mut replies = 0u32;
    let mut led_on = false;
    loop {
        // A read error (overrun, framing) loses bytes: the decoder will count the frame.
        let n = serial.read(&mut rx).unwrap_or(0);
        for &byte in rx.get(..n).unwrap_or(&[]) {
            let Some(mut reply) = session.receive(byte) else {
                continue;
            };
            if let ToHost::Status {
                stack_peak_bytes: peak,
                ..
            } = &mut reply
            {
                *peak = stack_peak_bytes();
            }
            if let Ok(frame) = encode_frame(&reply, &mut tx) {
                // A write error cannot be reported anywhere but the line itself.
                let _ = serial.write_all(frame);
            }
            after_reply(&reply, session.restart_requested());
            if session.restart_requested() {
                let _ = serial.flush();
                defmt::info!("restart requested: resetting");
                cortex_m::peripheral::SCB::sys_reset();
            }
            replies = replies.wrapping_add(1);
            if replies.is_multiple_of(HEARTBEAT_EVENTS) {
                led_on = !led_on;
                let _ = if led_on {
                    led.set_high()
                } else {
                    led.set_low()
                };
            }
        }
    }
}
