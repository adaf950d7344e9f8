//! An LD06 / LD19 lidar on USART1 of an STM32F411: its TX on PA10 (USART1 RX), 230 400 Bd
//! 8N1, read by an interrupt into a ring buffer.
//!
//! The lidar streams about 17 KB a second whatever the firmware does, and a USART holds
//! one byte: polled, every byte that arrives while the filter steps on a revolution would
//! be lost. The receive interrupt moves each byte into a ring of [`RING_BYTES`] (89 ms of
//! the line), which [`LidarUart`] (`embedded_io::Read`) empties as the session asks for a
//! revolution. When the ring is full the interrupt is switched off until the reader has
//! taken bytes from it: on a board the USART then overruns (the bytes lost show up as a
//! bad packet and skipped bytes in the reader's counters); under QEMU, whose USART holds
//! the line while its byte is unread, nothing is lost, so device and host read the same
//! bytes.

use core::cell::RefCell;
use core::convert::Infallible;
use core::sync::atomic::{AtomicBool, Ordering};

use cortex_m::interrupt::Mutex;
use embedded_hal_nb::serial::Read as _;
use heapless::spsc::{Consumer, Producer, Queue};
use static_cell::ConstStaticCell;
use stm32f4xx_hal::gpio::PA10;
use stm32f4xx_hal::pac::{self, interrupt};
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::rcc::Rcc;
use stm32f4xx_hal::serial::{Rx, RxListen};

/// The LD06's line rate (datasheet: 230 400 Bd, 8 data bits, no parity, 1 stop bit).
pub const LIDAR_BAUD: u32 = 230_400;

/// The ring's size: it holds one byte less, 2 047 bytes, 89 ms of the lidar's line. The
/// firmware must ask for the next revolution (`NextRevolution`) within that time of the
/// lidar sending it, or the bytes after are lost until it does.
pub const RING_BYTES: usize = 2048;

/// The ring between the interrupt and the reader, zero bytes at reset.
static RING: ConstStaticCell<Queue<u8, RING_BYTES>> = ConstStaticCell::new(Queue::new());

/// What the receive interrupt owns: the USART's receiver and the ring's writing end.
struct Receiver {
    rx: Rx<pac::USART1, u8>,
    ring: Producer<'static, u8>,
}

/// The receiver, handed to the interrupt by [`start`].
static RECEIVER: Mutex<RefCell<Option<Receiver>>> = Mutex::new(RefCell::new(None));

/// Set when the interrupt stopped because the ring was full; cleared by the reader when
/// it switches the interrupt on again.
static PAUSED: AtomicBool = AtomicBool::new(false);

/// The reading end: `embedded_io::Read` for `microslam-hal`'s `Ld06Uart`.
pub struct LidarUart {
    ring: Consumer<'static, u8>,
}

/// Configures USART1's receiver on PA10 at [`LIDAR_BAUD`] and starts its interrupt.
/// Call once.
pub fn start(usart: pac::USART1, pin: PA10, rcc: &mut Rcc) -> Option<LidarUart> {
    let mut rx = usart.rx(pin, LIDAR_BAUD.bps(), rcc).ok()?;
    let (producer, consumer) = RING.try_take()?.split();
    rx.listen();
    cortex_m::interrupt::free(|cs| {
        RECEIVER
            .borrow(cs)
            .replace(Some(Receiver { rx, ring: producer }));
    });
    // SAFETY: USART1's handler below only touches `RECEIVER` and `PAUSED`, which are
    // shared through a critical section and an atomic.
    unsafe { cortex_m::peripheral::NVIC::unmask(pac::Interrupt::USART1) };
    Some(LidarUart { ring: consumer })
}

#[interrupt]
fn USART1() {
    cortex_m::interrupt::free(|cs| {
        if let Some(r) = RECEIVER.borrow(cs).borrow_mut().as_mut() {
            r.drain();
        }
    });
}

impl Receiver {
    /// Moves the USART's bytes into the ring while it has room; on a full ring switches
    /// the interrupt off (at the USART and in the NVIC, so that a line the USART still
    /// holds up does not re-enter the handler) and leaves the byte in the USART.
    fn drain(&mut self) {
        loop {
            if !self.ring.ready() {
                self.rx.unlisten();
                cortex_m::peripheral::NVIC::mask(pac::Interrupt::USART1);
                PAUSED.store(true, Ordering::Release);
                return;
            }
            match self.rx.read() {
                Ok(byte) => {
                    // `ready()` above: there is room.
                    let _ = self.ring.enqueue(byte);
                }
                Err(nb::Error::WouldBlock) => return,
                // An overrun, framing or noise error: the read cleared the flag; the bytes
                // lost make a bad packet the decoder counts.
                Err(nb::Error::Other(_)) => {}
            }
        }
    }
}

impl LidarUart {
    /// With room in the ring: switches the interrupt on again if it stopped on a full
    /// ring, and takes what the USART holds (so that no byte waits for an interrupt
    /// edge that came while it was off).
    fn refill(&self) {
        cortex_m::interrupt::free(|cs| {
            let mut receiver = RECEIVER.borrow(cs).borrow_mut();
            let Some(r) = receiver.as_mut() else {
                return;
            };
            if PAUSED.load(Ordering::Acquire) {
                PAUSED.store(false, Ordering::Release);
                r.rx.listen();
                // SAFETY: as in `start`.
                unsafe { cortex_m::peripheral::NVIC::unmask(pac::Interrupt::USART1) };
            }
            r.drain();
        });
    }
}

impl embedded_io::ErrorType for LidarUart {
    type Error = Infallible;
}

impl embedded_io::Read for LidarUart {
    /// Waits for the first byte, then takes what the ring holds (up to `buf.len()`).
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        if buf.is_empty() {
            return Ok(0);
        }
        loop {
            let mut n = 0;
            for slot in buf.iter_mut() {
                let Some(byte) = self.ring.dequeue() else {
                    break;
                };
                *slot = byte;
                n += 1;
            }
            if n > 0 {
                if PAUSED.load(Ordering::Acquire) {
                    self.refill();
                }
                return Ok(n);
            }
            // Empty: take what the USART holds (and switch the interrupt on again).
            self.refill();
            core::hint::spin_loop();
        }
    }
}
