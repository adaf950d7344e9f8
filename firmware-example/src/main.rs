//! The firmware: the EKF in a `static`, the serial protocol of `microslam::wire` on the
//! board's UART, estimates streamed back for every event.
#![no_std]
#![no_main]

use cortex_m_rt::{ExceptionFrame, entry, exception};
use firmware_example::config::{EKF_CONFIG, EKF_LANDMARKS, Ekf, ZEROED_EKF_CONFIG};
use firmware_example::{board, serve, stack};
use microslam::wire::Session;
use panic_probe as _;
use static_cell::ConstStaticCell;

/// The EKF, zero bytes at reset (`.bss`), handed out once as `&'static mut`: the 18 KB
/// covariance never passes through the stack.
static EKF: ConstStaticCell<Ekf> = ConstStaticCell::new(Ekf::new(ZEROED_EKF_CONFIG));

#[entry]
fn main() -> ! {
    let ekf = EKF.take();
    let mut session = Session::<_, EKF_LANDMARKS>::new(ekf, EKF_CONFIG);
    let (mut serial, mut led) = board::init();
    defmt::info!(
        "microslam firmware: EKF with {} landmarks, waiting for frames",
        EKF_LANDMARKS
    );
    serve(&mut session, &mut serial, &mut led, stack::peak_bytes)
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    defmt::error!("HardFault at pc = {:#010x}", frame.pc());
    board::halt(3)
}
