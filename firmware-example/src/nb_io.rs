//! `embedded-io` over an `embedded-hal-nb` serial port, blocking: `read` waits for the
//! first byte and returns what is ready after it, `write` waits until one byte is taken.
//!
//! HAL serial ports (stm32f4xx-hal 0.23) offer `embedded_hal_nb::serial::{Read, Write}`;
//! their own `embedded_io::Write` returns `Ok(0)` when the transmitter is busy, which
//! `write_all` treats as an error, and they have no `embedded_io::Read`.

use embedded_hal_nb::serial;

/// A blocking `embedded_io` port over a non-blocking serial port.
pub struct NbSerial<S>(pub S);

/// An error of the underlying port.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NbSerialError(pub serial::ErrorKind);

impl embedded_io::Error for NbSerialError {
    fn kind(&self) -> embedded_io::ErrorKind {
        embedded_io::ErrorKind::Other
    }
}

impl<S: serial::ErrorType> embedded_io::ErrorType for NbSerial<S> {
    type Error = NbSerialError;
}

fn kind<E: serial::Error>(e: E) -> NbSerialError {
    NbSerialError(e.kind())
}

impl<S: serial::Read<u8>> embedded_io::Read for NbSerial<S> {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        let Some((first, rest)) = buf.split_first_mut() else {
            return Ok(0);
        };
        *first = nb::block!(self.0.read()).map_err(kind)?;
        let mut n = 1;
        for slot in rest {
            match self.0.read() {
                Ok(b) => *slot = b,
                Err(nb::Error::WouldBlock) => break,
                Err(nb::Error::Other(e)) => return Err(kind(e)),
            }
            n += 1;
        }
        Ok(n)
    }
}

impl<S: serial::Write<u8>> embedded_io::Write for NbSerial<S> {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        let Some(&first) = buf.first() else {
            return Ok(0);
        };
        nb::block!(self.0.write(first)).map_err(kind)?;
        Ok(1)
    }

    fn flush(&mut self) -> Result<(), Self::Error> {
        nb::block!(self.0.flush()).map_err(kind)
    }
}
