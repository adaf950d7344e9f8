//! An InvenSense MPU-6050 on an I2C bus: the robot's yaw rate.

use embedded_hal::delay::DelayNs;
use embedded_hal::i2c::I2c;
use mpu6050_dmp::address::Address;
use mpu6050_dmp::clock_source::ClockSource;
use mpu6050_dmp::config::DigitalLowPassFilter;
use mpu6050_dmp::gyro::GyroFullScale;
use mpu6050_dmp::sensor::Mpu6050;

/// The MPU-6050's identity register (`WHO_AM_I`).
const WHO_AM_I: u8 = 0x75;
/// What an MPU-6050 answers at its `WHO_AM_I` register, 0x75 (an MPU-6500 answers 0x70,
/// an MPU-9250 0x71).
pub const MPU6050_ID: u8 = 0x68;

/// Why the gyro could not be set up or read.
#[derive(Debug, PartialEq, Eq)]
pub enum ImuError<E> {
    /// The bus failed (no device at the address, a NAK, a stuck bus).
    Bus(E),
    /// The device at the address is not an MPU-6050: what it answered at `WHO_AM_I`.
    WrongDevice {
        /// The answer (0x68 for an MPU-6050).
        who_am_i: u8,
    },
    /// `calibrate` was asked for no sample.
    NoSamples,
}

impl<E: core::fmt::Debug> core::fmt::Display for ImuError<E> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Bus(e) => write!(f, "IMU bus error: {e:?}"),
            Self::WrongDevice { who_am_i } => write!(
                f,
                "the I2C device answers WHO_AM_I = {who_am_i:#04x}, an MPU-6050 answers {MPU6050_ID:#04x}"
            ),
            Self::NoSamples => f.write_str("IMU bias calibration asked for no sample"),
        }
    }
}

impl<E: core::fmt::Debug> core::error::Error for ImuError<E> {}

fn bus<I: I2c>(e: mpu6050_dmp::error::Error<I>) -> ImuError<I::Error> {
    match e {
        mpu6050_dmp::error::Error::WriteError(e) | mpu6050_dmp::error::Error::WriteReadError(e) => {
            ImuError::Bus(e)
        }
        mpu6050_dmp::error::Error::WrongDevice => ImuError::WrongDevice { who_am_i: 0 },
    }
}

/// The gyro's z axis as the robot's yaw rate, rad/s counter-clockwise, its bias removed.
pub struct YawGyro<I: I2c> {
    mpu: Mpu6050<I>,
    /// Raw counts per rad/s of the configured full scale.
    counts_per_rad_s: f32,
    /// −1 for a board mounted upside down (its z axis pointing down).
    sign: f32,
    /// The rate read at rest, rad/s (0 until [`YawGyro::calibrate`]).
    bias: f32,
}

impl<I: I2c> YawGyro<I> {
    /// Checks that the device at `address` is an MPU-6050 (a loud
    /// [`ImuError::WrongDevice`] otherwise, naming its answer), wakes it, clocks it from
    /// its gyro, and sets the gyro's full scale and the digital low-pass filter. The bus
    /// comes back with the error when the setup fails.
    pub fn new(
        mut i2c: I,
        address: Address,
        scale: GyroFullScale,
        filter: DigitalLowPassFilter,
        upside_down: bool,
    ) -> Result<Self, (ImuError<I::Error>, I)> {
        let mut id = [0u8; 1];
        if let Err(e) = i2c.write_read(address.0, &[WHO_AM_I], &mut id) {
            return Err((ImuError::Bus(e), i2c));
        }
        if id[0] != MPU6050_ID {
            return Err((ImuError::WrongDevice { who_am_i: id[0] }, i2c));
        }
        let mut mpu = match Mpu6050::new(i2c, address) {
            Ok(mpu) => mpu,
            Err(e) => return Err((bus(e.error), e.i2c)),
        };
        let configured = mpu
            .set_clock_source(ClockSource::Xgyro)
            .and_then(|()| mpu.set_gyro_full_scale(scale))
            .and_then(|()| mpu.set_digital_lowpass_filter(filter));
        if let Err(e) = configured {
            return Err((bus(e), mpu.release()));
        }
        Ok(Self {
            mpu,
            counts_per_rad_s: scale.scale() * (180.0 / core::f32::consts::PI),
            sign: if upside_down { -1.0 } else { 1.0 },
            bias: 0.0,
        })
    }

    /// The yaw rate now, rad/s, counter-clockwise seen from above, the bias removed.
    pub fn yaw_rate(&mut self) -> Result<f32, ImuError<I::Error>> {
        Ok(self.raw_rate()? - self.bias)
    }

    fn raw_rate(&mut self) -> Result<f32, ImuError<I::Error>> {
        let g = self.mpu.gyro().map_err(bus)?;
        Ok(self.sign * f32::from(g.z()) / self.counts_per_rad_s)
    }

    /// Measures the bias: the mean of `samples` reads `interval_us` apart, the robot at
    /// rest; later rates have it removed. Returns it, rad/s.
    pub fn calibrate(
        &mut self,
        samples: u16,
        interval_us: u32,
        delay: &mut impl DelayNs,
    ) -> Result<f32, ImuError<I::Error>> {
        if samples == 0 {
            return Err(ImuError::NoSamples);
        }
        let mut sum = 0.0f32;
        for _ in 0..samples {
            sum += self.raw_rate()?;
            delay.delay_us(interval_us);
        }
        self.bias = sum / f32::from(samples);
        Ok(self.bias)
    }

    /// The bias removed from every rate, rad/s.
    pub fn bias(&self) -> f32 {
        self.bias
    }

    /// Gives the bus back.
    pub fn release(self) -> I {
        self.mpu.release()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal_mock::eh1::delay::NoopDelay;
    use embedded_hal_mock::eh1::i2c::{Mock, Transaction};

    const A: u8 = 0x68;

    /// What the setup sends: WHO_AM_I, then read-modify-write of PWR_MGMT_1 (wake: bit 6
    /// cleared), PWR_MGMT_1 again (clock from the X gyro: 1), GYRO_CONFIG (full scale in
    /// bits 3–4) and CONFIG (the low-pass filter in bits 0–2).
    fn setup(who_am_i: u8) -> Vec<Transaction> {
        vec![
            Transaction::write_read(A, vec![0x75], vec![who_am_i]),
            Transaction::write_read(A, vec![0x6B], vec![0x40]),
            Transaction::write(A, vec![0x6B, 0x00]),
            Transaction::write_read(A, vec![0x6B], vec![0x00]),
            Transaction::write(A, vec![0x6B, 0x01]),
            Transaction::write_read(A, vec![0x1B], vec![0x00]),
            Transaction::write(A, vec![0x1B, 0x08]),
            Transaction::write_read(A, vec![0x1A], vec![0x00]),
            Transaction::write(A, vec![0x1A, 0x03]),
        ]
    }

    fn gyro_read(z: i16) -> Transaction {
        let [hi, lo] = z.to_be_bytes();
        Transaction::write_read(A, vec![0x43], vec![0, 0, 0, 0, hi, lo])
    }

    #[test]
    fn the_yaw_rate_in_radians_a_second_with_its_bias_removed() {
        let mut expect = setup(0x68);
        // ±500 °/s: 65.5 counts per °/s. At rest: 131 and 133 counts (2.0 and 2.03 °/s).
        expect.extend([gyro_read(131), gyro_read(133), gyro_read(131 + 6550)]);
        let i2c = Mock::new(&expect);
        let mut gyro = YawGyro::new(
            i2c,
            Address(A),
            GyroFullScale::Deg500,
            DigitalLowPassFilter::Filter3,
            false,
        )
        .map_err(|(e, _)| e)
        .expect("an MPU-6050");
        let bias = gyro.calibrate(2, 1000, &mut NoopDelay).expect("calibrated");
        assert!(
            (bias - (132.0 / 65.5f32).to_radians()).abs() < 1e-6,
            "{bias}"
        );
        // 100 °/s turning left, above the bias.
        let rate = gyro.yaw_rate().expect("a rate");
        assert!((rate - 100f32.to_radians() - (-1.0 / 65.5f32).to_radians()).abs() < 1e-5);
        gyro.release().done();
    }

    #[test]
    fn another_device_at_the_address_is_named_and_the_bus_returned() {
        let i2c = Mock::new(&[Transaction::write_read(A, vec![0x75], vec![0x70])]);
        let Err((err, mut i2c)) = YawGyro::new(
            i2c,
            Address(A),
            GyroFullScale::Deg500,
            DigitalLowPassFilter::Filter3,
            false,
        ) else {
            panic!("an MPU-6500 is not taken for an MPU-6050");
        };
        assert_eq!(err, ImuError::WrongDevice { who_am_i: 0x70 });
        assert!(err.to_string().contains("0x70"), "{err}");
        i2c.done();
    }

    #[test]
    fn upside_down_the_rate_changes_sign_and_no_samples_is_refused() {
        let mut expect = setup(0x68);
        expect.push(gyro_read(655));
        let mut gyro = YawGyro::new(
            Mock::new(&expect),
            Address(A),
            GyroFullScale::Deg500,
            DigitalLowPassFilter::Filter3,
            true,
        )
        .map_err(|(e, _)| e)
        .expect("an MPU-6050");
        assert_eq!(
            gyro.calibrate(0, 0, &mut NoopDelay),
            Err(ImuError::NoSamples)
        );
        let rate = gyro.yaw_rate().expect("a rate");
        assert!((rate + 10f32.to_radians()).abs() < 1e-6, "{rate}");
        gyro.release().done();
    }
}
