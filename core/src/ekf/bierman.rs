//! The kernels of Bierman's scalar update of `P = L D Lᵀ`: one step of the pivot chain, the
//! floor on a sighting's variance, and the passes that apply both scalar updates of a
//! sighting to one row of `L` or to two.

use crate::scalar::Real;

/// The measurement variance a scalar update uses: `r`, but at least `ε · h P hᵀ` (no
/// sighting is more precise than the rounding of its prediction; keeps the gain finite).
#[inline(always)]
pub(super) fn sighting_floor<T: Real>(r: T, hph: T) -> T {
    let floor = T::default_epsilon() * hph;
    if r > floor { r } else { floor }
}

/// One step of Bierman's chain: the new pivot `D α / α_next` and the column factor
/// `−f / α` (both zero when nothing before carried information; `D` kept when the
/// state does not enter the measurement).
#[inline(always)]
pub(super) fn bierman_step<T: Real>(d: T, f: T, alpha: T, next: T) -> (T, T) {
    if next <= T::ZERO {
        (d, T::ZERO)
    } else if alpha <= T::ZERO {
        (T::ZERO, T::ZERO)
    } else {
        (d * (alpha / next), -f / alpha)
    }
}

/// Both scalar updates on one row of `L` (its strict part), from its last entry to its
/// first: returns `(b₀, b₁)`, row `i` of `P h₀ᵀ` and of `P' h̃₁ᵀ`. The hot loop of the
/// update; not inlined, so the row and the terms keep their no-alias guarantees.
#[inline(never)]
pub(super) fn bierman_row<T: Real>(row: &mut [T], terms: &[[T; 4]], v1: T, v2: T) -> (T, T) {
    let (mut b0, mut b1) = (v1, v2);
    for (l, &[p1, w1, p2, w2]) in row.iter_mut().rev().zip(terms.iter().rev()) {
        let old = *l;
        let once = old + b0 * p1;
        b0 += old * w1;
        *l = once + b1 * p2;
        b1 += once * w2;
    }
    (b0, b1)
}

/// [`bierman_row`] on two rows at once over the same columns (each column's terms loaded
/// once for both): `a` and `b` are the rows' running `(b₀, b₁)` at the start; returns
/// both at the end.
#[inline(never)]
pub(super) fn bierman_rows<T: Real>(
    row_a: &mut [T],
    row_b: &mut [T],
    terms: &[[T; 4]],
    a: (T, T),
    b: (T, T),
) -> ((T, T), (T, T)) {
    let ((mut a0, mut a1), (mut b0, mut b1)) = (a, b);
    let rows = row_a.iter_mut().zip(row_b.iter_mut());
    for ((la, lb), &[p1, w1, p2, w2]) in rows.zip(terms).rev() {
        let (old_a, old_b) = (*la, *lb);
        let once_a = old_a + a0 * p1;
        let once_b = old_b + b0 * p1;
        a0 += old_a * w1;
        b0 += old_b * w1;
        *la = once_a + a1 * p2;
        *lb = once_b + b1 * p2;
        a1 += once_a * w2;
        b1 += once_b * w2;
    }
    ((a0, a1), (b0, b1))
}
