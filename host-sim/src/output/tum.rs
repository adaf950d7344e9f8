//! TUM trajectory files: `t x y z qx qy qz qw`, one pose a line.

use anyhow::{Context, Result};
use microslam::geometry::Pose2;
use std::io::Write;
use std::path::Path;

/// One TUM line for a planar pose (z = 0, rotation about z).
pub fn tum_line(stamp: f64, pose: &Pose2<f64>) -> String {
    let mut s = Vec::new();
    push_line(&mut s, stamp, pose);
    s.pop();
    String::from_utf8_lossy(&s).into_owned()
}

/// Poses as the text of a TUM file: a header line, then one pose a line.
pub fn tum_text(poses: impl IntoIterator<Item = (f64, Pose2<f64>)>) -> String {
    let mut text = Vec::with_capacity(4096);
    text.extend_from_slice(HEADER);
    for (t, p) in poses {
        push_line(&mut text, t, &p);
    }
    String::from_utf8_lossy(&text).into_owned()
}

/// The first line of every TUM file written here.
const HEADER: &[u8] = b"# timestamp x y z qx qy qz qw\n";

/// Writes poses as a TUM file.
pub fn write_tum(path: &Path, poses: impl IntoIterator<Item = (f64, Pose2<f64>)>) -> Result<()> {
    let file = super::create_file(path)?;
    let mut w = std::io::BufWriter::with_capacity(1 << 16, file);
    let mut line = Vec::with_capacity(128);
    line.extend_from_slice(HEADER);
    for (t, p) in poses {
        push_line(&mut line, t, &p);
        if line.len() > 4096 {
            w.write_all(&line)?;
            line.clear();
        }
    }
    w.write_all(&line)?;
    w.flush()
        .with_context(|| format!("cannot write {}", path.display()))
}

fn push_line(out: &mut Vec<u8>, stamp: f64, p: &Pose2<f64>) {
    let (s, c) = (p.theta / 2.0).sin_cos();
    let (Some(t), Some(x), Some(y), Some(qz), Some(qw)) = (
        scaled::<6>(stamp),
        scaled::<6>(p.x),
        scaled::<6>(p.y),
        scaled::<9>(s),
        scaled::<9>(c),
    ) else {
        // A value too large for integers (or NaN): number by number.
        push_fixed::<6>(out, stamp);
        out.push(b' ');
        push_fixed::<6>(out, p.x);
        out.push(b' ');
        push_fixed::<6>(out, p.y);
        out.extend_from_slice(b" 0 0 0 ");
        push_fixed::<9>(out, s);
        out.push(b' ');
        push_fixed::<9>(out, c);
        out.push(b'\n');
        return;
    };
    // Written backwards into one buffer, appended in one copy: formatting the numbers
    // one by one cost ~1 300 instructions a line, most of it in small copies.
    let mut line = Backwards::default();
    line.put(b'\n');
    line.put_fixed::<9>(qw);
    line.put(b' ');
    line.put_fixed::<9>(qz);
    for &b in b" 0 0 0 ".iter().rev() {
        line.put(b);
    }
    line.put_fixed::<6>(y);
    line.put(b' ');
    line.put_fixed::<6>(x);
    line.put(b' ');
    line.put_fixed::<6>(t);
    out.extend_from_slice(line.text());
}

/// `v` as `(negative, |v| · 10^D rounded half up)` when that fits the integer path: the
/// value [`push_fixed`] writes. `None` for NaN and values too large.
fn scaled<const D: u32>(v: f64) -> Option<(bool, u64)> {
    let scaled = v.abs() * 10u64.pow(D) as f64 + 0.5;
    if scaled.is_nan() || scaled >= 9.0e18 {
        return None;
    }
    let n = scaled as u64; // truncating x + 0.5 rounds x ≥ 0
    Some((v < 0.0 && n != 0, n))
}

/// A TUM line written from its end: five numbers of at most 21 bytes (a sign, 13 integer
/// digits with `D` = 6 or 10 with `D` = 9, the point and `D` decimals) and 11 other bytes.
struct Backwards {
    bytes: [u8; 128],
    /// Index of the first byte written.
    start: usize,
}

impl Default for Backwards {
    fn default() -> Self {
        Self {
            bytes: [0; 128],
            start: 128,
        }
    }
}

impl Backwards {
    fn put(&mut self, b: u8) {
        self.start -= 1;
        self.bytes[self.start] = b;
    }

    fn put_pair(&mut self, n: u64) {
        let d = n as usize * 2;
        self.put(PAIRS[d + 1]);
        self.put(PAIRS[d]);
    }

    /// `(negative, n)` from [`scaled`], as `n / 10^D` with `D` digits after the point.
    fn put_fixed<const D: u32>(&mut self, (negative, n): (bool, u64)) {
        let unit = 10u64.pow(D);
        let (mut int, mut frac) = (n / unit, n % unit);
        for _ in 0..D / 2 {
            self.put_pair(frac % 100);
            frac /= 100;
        }
        if D % 2 == 1 {
            self.put(b'0' + frac as u8);
        }
        self.put(b'.');
        while int >= 100 {
            self.put_pair(int % 100);
            int /= 100;
        }
        if int >= 10 {
            self.put_pair(int);
        } else {
            self.put(b'0' + int as u8);
        }
        if negative {
            self.put(b'-');
        }
    }

    fn text(&self) -> &[u8] {
        &self.bytes[self.start..]
    }
}

/// Appends `v` with 6 or 9 digits after the point, by integer arithmetic: float
/// formatting dominated the writing of long trajectories. Values too large for it fall
/// back to the standard formatter.
fn push_fixed<const D: u32>(out: &mut Vec<u8>, v: f64) {
    match scaled::<D>(v) {
        Some(n) => {
            let mut text = Backwards::default();
            text.put_fixed::<D>(n);
            out.extend_from_slice(text.text());
        }
        None => {
            let _ = write!(out, "{v:.*}", D as usize);
        }
    }
}

/// "00" … "99": two digits per division.
const PAIRS: &[u8; 200] = b"0001020304050607080910111213141516171819\
2021222324252627282930313233343536373839\
4041424344454647484950515253545556575859\
6061626364656667686970717273747576777879\
8081828384858687888990919293949596979899";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternion_of_a_yaw() {
        let l = tum_line(1.5, &Pose2::new(1.0, -2.0, std::f64::consts::FRAC_PI_2));
        assert_eq!(
            l,
            "1.500000 1.000000 -2.000000 0 0 0 0.707106781 0.707106781"
        );
        let l = tum_line(
            1248444187.156,
            &Pose2::new(-0.0000004, -0.25, -std::f64::consts::PI),
        );
        assert_eq!(
            l,
            "1248444187.156000 0.000000 -0.250000 0 0 0 -1.000000000 0.000000000"
        );
    }

    #[test]
    fn a_value_too_large_for_the_integer_path_is_written_in_full() {
        let l = tum_line(1e300, &Pose2::new(-2.5, f64::NAN, 0.0));
        assert_eq!(
            l,
            format!("{:.6} -2.500000 NaN 0 0 0 0.000000000 1.000000000", 1e300)
        );
    }

    /// The integer digits against std's integer formatting of the same rounding, over
    /// every digit count and sign.
    #[test]
    fn fixed_digits_match_integer_formatting() {
        fn reference(v: f64, digits: u32) -> String {
            let unit = 10u64.pow(digits);
            let n = (v.abs() * unit as f64 + 0.5) as u64;
            let sign = if v < 0.0 && n != 0 { "-" } else { "" };
            let d = digits as usize;
            format!("{sign}{}.{:0d$}", n / unit, n % unit)
        }
        let mut values: Vec<f64> = vec![0.0, -0.0, 1e-12, -4e-7, 0.5, 0.999_999_9, 9.999_999_5];
        let mut x = 1.234_567_891_234_5_f64;
        for _ in 0..40 {
            values.extend([x, -x, x.trunc(), x + 0.000_000_5]);
            x *= 3.7;
        }
        for &v in values.iter().filter(|v| v.abs() < 9.0e9) {
            let mut six = Vec::new();
            push_fixed::<6>(&mut six, v);
            assert_eq!(String::from_utf8(six).unwrap(), reference(v, 6), "{v}");
            let mut nine = Vec::new();
            push_fixed::<9>(&mut nine, v);
            assert_eq!(String::from_utf8(nine).unwrap(), reference(v, 9), "{v}");
        }
        let mut big = Vec::new();
        push_fixed::<6>(&mut big, -1e300);
        assert_eq!(String::from_utf8(big).unwrap(), format!("{:.6}", -1e300));
    }
}
