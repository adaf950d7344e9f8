//! Standard normal draws in `f32` for the prediction: the ziggurat method of Marsaglia
//! and Tsang (2000) with 128 layers, one 32-bit random number per draw in 98.8 % of the
//! draws and `f32` arithmetic only.
//!
//! `rand_distr`'s `StandardNormal` draws an `f64` (a 64-bit random number and `f64`
//! arithmetic) and converts it: on a Cortex-M4F, whose FPU is single precision, each
//! draw costs a few hundred instructions of software floating point, three per particle
//! and step. Here the fast path is a table lookup, an integer-to-float conversion, a
//! multiplication and a comparison. Same results on every target (IEEE `f32` arithmetic
//! and `libm`).

use rand_core::RngCore;

/// Layers of the ziggurat.
const LAYERS: usize = 128;
/// Start of the tail: the right edge of the bottom layer.
const TAIL: f32 = 3.442_619_8;

/// Right edges of the layers (Marsaglia and Tsang's `x_i`, `f(x) = exp(−x²/2)`):
/// `X[0] = v / f(r)` (the bottom layer with its tail as a rectangle of the same area
/// `v = 9.912563e−3`), `X[1] = r = 3.4426198`, `X[i+1] = sqrt(−2 ln(v / X[i] + f(X[i])))`,
/// `X[128] = 0`, rounded to `f32` (the test `table_follows_the_recurrence` recomputes
/// it in `f64`).
static X: [f32; LAYERS + 1] = [
    3.7130861, 3.4426198, 3.223085, 3.0832288, 2.9786963, 2.894344, 2.8231254, 2.7611694,
    2.7061136, 2.6564064, 2.6109722, 2.5690336, 2.5300097, 2.4934545, 2.4590182, 2.4264207,
    2.3954344, 2.3658714, 2.3375752, 2.3104136, 2.284274, 2.2590597, 2.2346864, 2.2110815,
    2.1881804, 2.1659267, 2.1442702, 2.1231656, 2.1025732, 2.0824564, 2.0627823, 2.0435216,
    2.024647, 2.0061338, 1.9879596, 1.9701033, 1.9525458, 1.9352692, 1.9182574, 1.9014946,
    1.8849671, 1.8686612, 1.8525645, 1.8366655, 1.820953, 1.8054168, 1.7900469, 1.7748344,
    1.7597703, 1.7448461, 1.7300541, 1.7153867, 1.7008367, 1.6863968, 1.6720607, 1.6578219,
    1.6436741, 1.6296115, 1.6156281, 1.6017184, 1.5878769, 1.5740982, 1.5603772, 1.5467088,
    1.5330878, 1.5195096, 1.505969, 1.4924614, 1.478982, 1.465526, 1.4520886, 1.4386653, 1.4252512,
    1.4118418, 1.3984319, 1.385017, 1.3715922, 1.3581525, 1.3446927, 1.331208, 1.3176928,
    1.3041419, 1.2905496, 1.2769103, 1.2632179, 1.2494665, 1.2356495, 1.2217603, 1.2077918,
    1.1937367, 1.1795874, 1.1653357, 1.1509728, 1.1364899, 1.121877, 1.1071236, 1.0922189,
    1.0771506, 1.061906, 1.0464709, 1.0308303, 1.0149674, 0.99886423, 0.9825008, 0.96585506,
    0.9489026, 0.9316162, 0.9139652, 0.8959153, 0.87742746, 0.85845685, 0.83895224, 0.8188539,
    0.79809207, 0.77658397, 0.7542307, 0.7309119, 0.7064796, 0.6807479, 0.6534786, 0.6243586,
    0.5929629, 0.55869216, 0.52065605, 0.47743782, 0.42654797, 0.36287144, 0.27232087, 0.0,
];

/// The unnormalised density `exp(−x²/2)`.
#[inline]
fn density(x: f32) -> f32 {
    libm::expf(-0.5 * x * x)
}

/// A uniform draw in `(0, 1]` from 24 random bits.
#[inline]
fn open_unit<R: RngCore + ?Sized>(rng: &mut R) -> f32 {
    ((rng.next_u32() >> 8) + 1) as f32 * (1.0 / 16_777_216.0)
}

/// One standard normal draw (mean 0, standard deviation 1).
#[inline]
pub fn standard_normal<R: RngCore + ?Sized>(rng: &mut R) -> f32 {
    loop {
        let bits = rng.next_u32();
        let i = (bits & (LAYERS as u32 - 1)) as usize;
        // 24 bits of magnitude in [0, 1), bit 7 the sign.
        let u = (bits >> 8) as f32 * (1.0 / 16_777_216.0);
        let negative = bits & 0x80 != 0;
        let (Some(&xi), Some(&next)) = (X.get(i), X.get(i + 1)) else {
            continue;
        };
        let x = u * xi;
        let sign = |v: f32| if negative { -v } else { v };
        if x < next {
            return sign(x);
        }
        if i == 0 {
            // The tail beyond r (Marsaglia 1964).
            loop {
                let a = -libm::logf(open_unit(rng)) / TAIL;
                let b = -libm::logf(open_unit(rng));
                if 2.0 * b > a * a {
                    return sign(TAIL + a);
                }
            }
        }
        // The wedge between the layer's rectangle and the density.
        let f_next = density(next);
        if f_next + open_unit(rng) * (density(xi) - f_next) < density(x) {
            return sign(x);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_core::SeedableRng;
    use rand_xoshiro::Xoshiro128PlusPlus;

    #[test]
    fn table_follows_the_recurrence() {
        let r = 3.442_619_855_899_f64;
        let v = 9.912_563_035_262_17e-3_f64;
        let f = |x: f64| (-0.5 * x * x).exp();
        let mut x = [0.0f64; LAYERS + 1];
        x[0] = v / f(r);
        x[1] = r;
        for i in 1..LAYERS - 1 {
            x[i + 1] = (-2.0 * (v / x[i] + f(x[i])).ln()).sqrt();
        }
        for (i, (table, exact)) in X.iter().zip(x).enumerate() {
            assert_eq!(*table, exact as f32, "layer {i}");
        }
        // The top layer closes the ziggurat: its rectangle reaches f(0) = 1.
        assert!((v / x[LAYERS - 1] + f(x[LAYERS - 1]) - 1.0).abs() < 1e-6);
        assert_eq!(TAIL, r as f32);
    }

    #[test]
    fn moments_and_tails_are_normal() {
        let mut rng = Xoshiro128PlusPlus::seed_from_u64(11);
        let n = 400_000;
        let (mut s1, mut s2, mut s4) = (0.0f64, 0.0f64, 0.0f64);
        let mut beyond = [0u32; 3]; // |z| > 1, 2, 3
        for _ in 0..n {
            let z = f64::from(standard_normal(&mut rng));
            s1 += z;
            s2 += z * z;
            s4 += z * z * z * z;
            for (k, b) in beyond.iter_mut().enumerate() {
                if z.abs() > (k + 1) as f64 {
                    *b += 1;
                }
            }
        }
        let n = f64::from(n);
        // Standard errors: mean 1/√n = 0.0016, variance √(2/n) = 0.0022, E z⁴ √(96/n) = 0.015.
        assert!((s1 / n).abs() < 0.008, "mean {}", s1 / n);
        assert!((s2 / n - 1.0).abs() < 0.011, "variance {}", s2 / n);
        assert!((s4 / n - 3.0).abs() < 0.08, "fourth moment {}", s4 / n);
        // P(|z| > k) = 0.3173, 0.0455, 0.0027 (± 5 standard errors).
        for (b, p) in beyond.iter().zip([0.317_31_f64, 0.045_50, 0.002_70]) {
            let got = f64::from(*b) / n;
            let se = (p * (1.0 - p) / n).sqrt();
            assert!((got - p).abs() < 5.0 * se, "{got} vs {p}");
        }
    }
}
