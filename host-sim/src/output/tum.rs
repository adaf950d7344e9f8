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

/// Writes a slice of poses as a TUM file, the same bytes as [`write_tum`]: two halves of
/// each window of lines are formatted side by side (rayon), then written in order.
pub fn write_tum_slice<S: Sync>(
    path: &Path,
    items: &[S],
    pose: impl Fn(&S) -> (f64, Pose2<f64>) + Sync,
) -> Result<()> {
    /// Lines per half-window: two reused buffers of ~300 KB.
    const HALF: usize = 4096;
    let format = |text: &mut Vec<u8>, part: &[S]| {
        text.clear();
        for item in part {
            let (t, p) = pose(item);
            push_line(text, t, &p);
        }
    };
    let file =
        std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut w = std::io::BufWriter::with_capacity(1 << 16, file);
    w.write_all(HEADER)?;
    let (mut first, mut second) = (Vec::new(), Vec::new());
    for window in items.chunks(2 * HALF) {
        let (a, b) = window.split_at(window.len().min(HALF));
        rayon::join(|| format(&mut first, a), || format(&mut second, b));
        w.write_all(&first)?;
        w.write_all(&second)?;
    }
    w.flush()
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Writes poses as a TUM file.
pub fn write_tum(path: &Path, poses: impl IntoIterator<Item = (f64, Pose2<f64>)>) -> Result<()> {
    let file =
        std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
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
}

/// Appends `v` with 6 or 9 digits after the point, by integer arithmetic: float
/// formatting dominated the writing of long trajectories. Values too large for it fall
/// back to the standard formatter.
fn push_fixed<const D: u32>(out: &mut Vec<u8>, v: f64) {
    let unit = 10u64.pow(D);
    let scaled = v.abs() * unit as f64 + 0.5;
    if scaled.is_nan() || scaled >= 9.0e18 {
        let _ = write!(out, "{v:.*}", D as usize);
        return;
    }
    let n = scaled as u64; // truncating x + 0.5 rounds x ≥ 0
    if v < 0.0 && n != 0 {
        out.push(b'-');
    }
    push_digits(out, n / unit, 1);
    out.push(b'.');
    push_digits(out, n % unit, D as usize);
}

/// "00" … "99": two digits per division.
const PAIRS: &[u8; 200] = b"0001020304050607080910111213141516171819\
2021222324252627282930313233343536373839\
4041424344454647484950515253545556575859\
6061626364656667686970717273747576777879\
8081828384858687888990919293949596979899";

/// Appends the decimal digits of `n`, zero-padded to at least `min_digits` (≤ 20).
fn push_digits(out: &mut Vec<u8>, mut n: u64, min_digits: usize) {
    let mut buf = [b'0'; 20];
    let mut i = buf.len();
    while n >= 100 {
        let d = (n % 100) as usize * 2;
        n /= 100;
        i -= 2;
        buf[i..i + 2].copy_from_slice(&PAIRS[d..d + 2]);
    }
    if n >= 10 {
        let d = n as usize * 2;
        i -= 2;
        buf[i..i + 2].copy_from_slice(&PAIRS[d..d + 2]);
    } else {
        i -= 1;
        buf[i] = b'0' + n as u8;
    }
    let start = i.min(buf.len().saturating_sub(min_digits));
    out.extend_from_slice(&buf[start..]);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parallel_chunks_write_the_same_bytes() {
        let poses: Vec<(f64, Pose2<f64>)> = (0..20_000)
            .map(|i| {
                let k = f64::from(i);
                (
                    1e9 + 0.013 * k,
                    Pose2::new(k.sin() * 40.0, -0.001 * k, (0.37 * k).cos() * 3.0),
                )
            })
            .collect();
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.tum"), dir.path().join("b.tum"));
        write_tum(&a, poses.iter().copied()).unwrap();
        write_tum_slice(&b, &poses, |p| *p).unwrap();
        let (a, b) = (std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
        assert_eq!(a.iter().filter(|&&c| c == b'\n').count(), 20_001);
        assert_eq!(a, b);
    }

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
