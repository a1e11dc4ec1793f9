//! Numbers the law can be written once for: `f64`, dual numbers, and
//! [`Lanes`], `W` agents side by side for SIMD.
//!
//! [`Lanes`] is a plain `[f64; W]` whose operations are element-wise loops that
//! the compiler turns into vector instructions (SSE2 on every x86-64, wider where
//! the build or a runtime dispatch enables it). There is no fused multiply-add
//! anywhere (Rust never contracts `a * b + c`), so each lane of a [`Lanes`]
//! computation is bit for bit the same `f64` computation: the vectorised law
//! *is* the scalar law. Only the transcendental functions differ from the
//! platform's `libm`: [`Lanes::sin_cos`] and [`Lanes::atan2`] are branch-free
//! polynomial versions (Cody–Waite reduction and the Cephes minimax
//! coefficients), accurate to a few units in the last place.

// Lane loops index several arrays in step (and vectorise as such); the
// polynomial coefficients are quoted as Cephes publishes them.
#![allow(clippy::needless_range_loop, clippy::excessive_precision)]

use std::ops::{Add, BitAnd, BitOr, BitXor, Div, Mul, Neg, Not, Sub};

/// What the generic parts of the law need of a number: field arithmetic with
/// itself and with `f64` constants on the right. `f64`, every `num_dual`
/// dual number and [`Lanes`] qualify.
pub trait Real:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + Add<f64, Output = Self>
    + Sub<f64, Output = Self>
    + Mul<f64, Output = Self>
    + Div<f64, Output = Self>
    + From<f64>
{
}

impl<T> Real for T where
    T: Copy
        + Add<Output = T>
        + Sub<Output = T>
        + Mul<Output = T>
        + Div<Output = T>
        + Neg<Output = T>
        + Add<f64, Output = T>
        + Sub<f64, Output = T>
        + Mul<f64, Output = T>
        + Div<f64, Output = T>
        + From<f64>
{
}

/// `W` values of `f64`, operated on element-wise (one agent per lane).
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(32))]
pub struct Lanes<const W: usize>(pub [f64; W]);

/// A per-lane condition: all ones (true) or all zeros (false), as the
/// comparison instructions produce.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Mask<const W: usize>(pub [u64; W]);

macro_rules! lanewise {
    ($tr:ident, $f:ident, $op:tt) => {
        impl<const W: usize> $tr for Lanes<W> {
            type Output = Lanes<W>;
            #[inline(always)]
            fn $f(self, o: Lanes<W>) -> Lanes<W> {
                let mut r = self.0;
                for i in 0..W {
                    r[i] $op o.0[i];
                }
                Lanes(r)
            }
        }
        impl<const W: usize> $tr<f64> for Lanes<W> {
            type Output = Lanes<W>;
            #[inline(always)]
            fn $f(self, o: f64) -> Lanes<W> {
                let mut r = self.0;
                for x in &mut r {
                    *x $op o;
                }
                Lanes(r)
            }
        }
    };
}
lanewise!(Add, add, +=);
lanewise!(Sub, sub, -=);
lanewise!(Mul, mul, *=);
lanewise!(Div, div, /=);

impl<const W: usize> Neg for Lanes<W> {
    type Output = Lanes<W>;
    #[inline(always)]
    fn neg(self) -> Lanes<W> {
        let mut r = self.0;
        for x in &mut r {
            *x = -*x;
        }
        Lanes(r)
    }
}

impl<const W: usize> From<f64> for Lanes<W> {
    #[inline(always)]
    fn from(x: f64) -> Lanes<W> {
        Lanes([x; W])
    }
}

impl<const W: usize> BitAnd for Mask<W> {
    type Output = Mask<W>;
    #[inline(always)]
    fn bitand(self, o: Mask<W>) -> Mask<W> {
        let mut r = self.0;
        for i in 0..W {
            r[i] &= o.0[i];
        }
        Mask(r)
    }
}

impl<const W: usize> BitOr for Mask<W> {
    type Output = Mask<W>;
    #[inline(always)]
    fn bitor(self, o: Mask<W>) -> Mask<W> {
        let mut r = self.0;
        for i in 0..W {
            r[i] |= o.0[i];
        }
        Mask(r)
    }
}

impl<const W: usize> Not for Mask<W> {
    type Output = Mask<W>;
    #[inline(always)]
    fn not(self) -> Mask<W> {
        let mut r = self.0;
        for x in &mut r {
            *x = !*x;
        }
        Mask(r)
    }
}

impl<const W: usize> BitXor for Mask<W> {
    type Output = Mask<W>;
    #[inline(always)]
    fn bitxor(self, o: Mask<W>) -> Mask<W> {
        let mut r = self.0;
        for i in 0..W {
            r[i] ^= o.0[i];
        }
        Mask(r)
    }
}

impl<const W: usize> Mask<W> {
    /// The bits as `f64`s.
    #[inline(always)]
    fn float(self) -> Lanes<W> {
        Lanes(self.0.map(f64::from_bits))
    }

    /// Each lane's bits shifted left by `k`.
    #[inline(always)]
    fn shl(self, k: u32) -> Mask<W> {
        Mask(self.0.map(|b| b << k))
    }

    /// Lane-wise wrapping sum of the bits as integers.
    #[inline(always)]
    fn add(self, o: Mask<W>) -> Mask<W> {
        let mut r = self.0;
        for i in 0..W {
            r[i] = r[i].wrapping_add(o.0[i]);
        }
        Mask(r)
    }

    /// Whether any lane is true.
    #[inline(always)]
    pub fn any(self) -> bool {
        self.0.iter().fold(0, |a, &m| a | m) != 0
    }

    /// Whether every lane is true.
    #[inline(always)]
    pub fn all(self) -> bool {
        self.0.iter().fold(!0, |a, &m| a & m) != 0
    }
}

/// `2/π`.
const FRAC_2_PI: f64 = std::f64::consts::FRAC_2_PI;
/// `π/2` in three parts whose products with a whole number below 2³⁰ are exact
/// (Cephes `sin.c`'s `DP1..DP3`, doubled).
const PIO2_1: f64 = 1.570_796_251_296_997_070_31;
const PIO2_2: f64 = 7.549_789_415_861_596_353_36e-8;
const PIO2_3: f64 = 5.390_302_858_158_119_052_9e-15;
/// Beyond this `|θ|` the three-part reduction loses accuracy: such lanes fall
/// back to the platform's `sin_cos`.
const SIN_COS_LIMIT: f64 = 5.0e8;
/// [`Lanes::sin_cos_turned`] takes turns below this, rad.
const TURN_LIMIT: f64 = 0.05;
/// `sin δ = δ + δ z (…)`, `z = δ²`: `−1/3! + z/5! − z²/7!`, Horner order.
const TURN_SIN: [f64; 3] = [-1.0 / 5040.0, 1.0 / 120.0, -1.0 / 6.0];
/// `cos δ − 1 = z (…)`: `−1/2! + z/4! − z²/6! + z³/8!`, Horner order.
const TURN_COS: [f64; 4] = [1.0 / 40320.0, -1.0 / 720.0, 1.0 / 24.0, -0.5];
/// `1.5 · 2⁵²`: adding and subtracting it rounds to the nearest whole number
/// (ties to even) for `|x| < 2⁵¹`, and leaves that number in the low bits.
const ROUND_MAGIC: f64 = 6_755_399_441_055_744.0;
/// Cephes `sin.c`: `sin x = x + x³ S(x²)` on `[−π/4, π/4]`.
const SIN_COEFFS: [f64; 6] = [
    1.589_623_015_765_465_680_60e-10,
    -2.505_074_776_285_780_728_66e-8,
    2.755_731_362_138_572_452_13e-6,
    -1.984_126_982_958_953_859_96e-4,
    8.333_333_333_322_118_588_78e-3,
    -1.666_666_666_666_663_072_95e-1,
];
/// Cephes `sin.c`: `cos x = 1 − x²/2 + x⁴ C(x²)` on `[−π/4, π/4]`.
const COS_COEFFS: [f64; 6] = [
    -1.135_853_652_138_768_173_00e-11,
    2.087_570_084_197_473_167_78e-9,
    -2.755_731_417_929_673_881_12e-7,
    2.480_158_728_885_170_453_48e-5,
    -1.388_888_888_887_305_641_16e-3,
    4.166_666_666_666_659_292_18e-2,
];
/// Cephes `atan.c`: `atan x = x + x³ P(x²)/Q(x²)` on `[−0.66, 0.66]`.
const ATAN_P: [f64; 5] = [
    -8.750_608_600_031_904_122_785e-1,
    -1.615_753_718_733_365_076_637e1,
    -7.500_855_792_314_704_667_340e1,
    -1.228_866_684_490_136_173_410e2,
    -6.485_021_904_942_025_371_773e1,
];
/// The monic denominator `Q`.
const ATAN_Q: [f64; 6] = [
    1.0,
    2.485_846_490_142_306_297_962e1,
    1.650_270_098_316_988_542_046e2,
    4.328_810_604_912_902_668_951e2,
    4.853_903_996_359_136_964_868e2,
    1.945_506_571_482_613_964_425e2,
];
/// `tan(3π/8)`.
const TAN_3PI_8: f64 = 2.414_213_562_373_095_048_80;
/// `π/2 − fl(π/2)`: the bits `fl(π/2)` lacks.
const PIO2_LO: f64 = 6.123_233_995_736_765_886_130e-17;

impl<const W: usize> Lanes<W> {
    /// All lanes `x`.
    #[inline(always)]
    pub fn splat(x: f64) -> Lanes<W> {
        Lanes([x; W])
    }

    /// The first `W` values of `s` (which must hold at least `W`).
    #[inline(always)]
    pub fn from_slice(s: &[f64]) -> Lanes<W> {
        Lanes(std::array::from_fn(|i| s[i]))
    }

    /// Lane `i`.
    #[inline(always)]
    pub fn lane(self, i: usize) -> f64 {
        self.0[i]
    }

    #[inline(always)]
    fn map(self, f: impl Fn(f64) -> f64) -> Lanes<W> {
        let mut r = self.0;
        for x in &mut r {
            *x = f(*x);
        }
        Lanes(r)
    }

    #[inline(always)]
    pub(crate) fn compare(self, o: Lanes<W>, f: impl Fn(f64, f64) -> bool) -> Mask<W> {
        let mut r = [0u64; W];
        for i in 0..W {
            r[i] = if f(self.0[i], o.0[i]) { u64::MAX } else { 0 };
        }
        Mask(r)
    }

    /// `self < o` per lane.
    #[inline(always)]
    pub fn lt(self, o: Lanes<W>) -> Mask<W> {
        self.compare(o, |a, b| a < b)
    }

    /// `self > o` per lane.
    #[inline(always)]
    pub fn gt(self, o: Lanes<W>) -> Mask<W> {
        self.compare(o, |a, b| a > b)
    }

    /// `self == o` per lane.
    #[inline(always)]
    pub fn eq_lanes(self, o: Lanes<W>) -> Mask<W> {
        self.compare(o, |a, b| a == b)
    }

    /// Lanes that are neither infinite nor NaN.
    #[inline(always)]
    pub fn finite(self) -> Mask<W> {
        self.abs().compare(Lanes::splat(f64::MAX), |a, b| a <= b)
    }

    /// Lanes whose sign bit is set (negative numbers, −0, negative NaNs).
    #[inline(always)]
    pub fn sign_mask(self) -> Mask<W> {
        let mut r = [0u64; W];
        for i in 0..W {
            r[i] = 0u64.wrapping_sub(self.0[i].to_bits() >> 63);
        }
        Mask(r)
    }

    /// `if m { a } else { b }` per lane, bitwise.
    #[inline(always)]
    pub fn select(m: Mask<W>, a: Lanes<W>, b: Lanes<W>) -> Lanes<W> {
        ((m & a.bits()) | (!m & b.bits())).float()
    }

    /// The bits of each lane.
    #[inline(always)]
    fn bits(self) -> Mask<W> {
        Mask(self.0.map(f64::to_bits))
    }

    /// `|x|`.
    #[inline(always)]
    pub fn abs(self) -> Lanes<W> {
        self.map(|x| f64::from_bits(x.to_bits() & !(1u64 << 63)))
    }

    /// The larger of each pair (`o` when either is NaN).
    #[inline(always)]
    pub fn max(self, o: Lanes<W>) -> Lanes<W> {
        Lanes::select(self.gt(o), self, o)
    }

    /// The smaller of each pair (`o` when either is NaN).
    #[inline(always)]
    pub fn min(self, o: Lanes<W>) -> Lanes<W> {
        Lanes::select(self.lt(o), self, o)
    }

    /// `√x` (correctly rounded, like `f64::sqrt`).
    #[inline(always)]
    pub fn sqrt(self) -> Lanes<W> {
        self.map(f64::sqrt)
    }

    /// `self` with its bits xored with `m` (a sign flip where `m` is the sign bit).
    #[inline(always)]
    fn flip_signs(self, m: Mask<W>) -> Lanes<W> {
        let mut r = self.0;
        for i in 0..W {
            r[i] = f64::from_bits(r[i].to_bits() ^ m.0[i]);
        }
        Lanes(r)
    }

    /// `sign(s) |self|`: `self` with the sign bit of `s`.
    #[inline(always)]
    pub fn copysign(self, s: Lanes<W>) -> Lanes<W> {
        let mut r = self.0;
        for i in 0..W {
            r[i] = f64::from_bits(
                (r[i].to_bits() & !(1u64 << 63)) | (s.0[i].to_bits() & (1u64 << 63)),
            );
        }
        Lanes(r)
    }

    /// `c[0] x^(n−1) + … + c[n−1]` by Horner's rule.
    #[inline(always)]
    fn poly<const N: usize>(self, c: &[f64; N]) -> Lanes<W> {
        let mut acc = Lanes::splat(c[0]);
        for &k in &c[1..] {
            acc = acc * self + k;
        }
        acc
    }

    /// `(sin x, cos x)` per lane, branch-free.
    ///
    /// `x = n π/2 + y` with `n` the nearest whole number and `|y| ≤ π/4`
    /// (Cody–Waite, π/2 in three parts); Cephes' minimax polynomials on `y`;
    /// `n mod 4` swaps and negates. Within 2 ulp of the correctly rounded
    /// values for `|x| ≤ 10⁹` (tested against `f64::sin_cos`); lanes beyond
    /// (or not finite) take `f64::sin_cos`.
    #[inline(always)]
    pub fn sin_cos(self) -> (Lanes<W>, Lanes<W>) {
        let x = self;
        let shifted = x * FRAC_2_PI + ROUND_MAGIC;
        let n = shifted - ROUND_MAGIC;
        let y = ((x - n * PIO2_1) - n * PIO2_2) - n * PIO2_3;
        let z = y * y;
        let s = y + y * z * z.poly(&SIN_COEFFS);
        let c = (-(z * 0.5) + 1.0) + z * z * z.poly(&COS_COEFFS);
        // n mod 4 from the low bits of the shifted value: bit 0 swaps sin and
        // cos; sin is negated for n ≡ 2, 3 and cos for n ≡ 1, 2.
        let q = shifted.bits();
        let swap = Mask((q & Mask([1; W])).0.map(|b| 0u64.wrapping_sub(b)));
        let (mut sin, mut cos) = (Lanes::select(swap, c, s), Lanes::select(swap, s, c));
        sin = sin.flip_signs((q & Mask([2; W])).shl(62));
        cos = cos.flip_signs((q.add(Mask([1; W])) & Mask([2; W])).shl(62));
        let wild = !(x.abs().lt(Lanes::splat(SIN_COS_LIMIT)));
        if wild.any() {
            for i in 0..W {
                if wild.0[i] != 0 {
                    (sin.0[i], cos.0[i]) = x.0[i].sin_cos();
                }
            }
        }
        (sin, cos)
    }

    /// `(sin(θ + δ), cos(θ + δ))` from `sin θ`, `cos θ` and a small turn `δ`
    /// (`self`), by the angle-sum formulas with Taylor series of `sin δ` and
    /// `cos δ − 1`; `None` when some lane has `|δ| ≥ 0.05` (or is not
    /// finite), and the caller takes [`Lanes::sin_cos`] of the new angle.
    ///
    /// An RK4 stage turns a robot by `δ = c·dt·ω` from the step's start, a few
    /// milliradians: this costs a third of [`Lanes::sin_cos`] and is within a
    /// few ulp of it (the series' remainders, `δ⁹/9!` and `δ¹⁰/10!`, are below
    /// 10⁻¹⁷ at the limit; tested). It is `sin`, `cos` of the exact `θ + δ`,
    /// while the state holds `θ + δ` rounded: the two differ by half an ulp of
    /// `θ`.
    #[inline(always)]
    pub fn sin_cos_turned(self, sin: Lanes<W>, cos: Lanes<W>) -> Option<(Lanes<W>, Lanes<W>)> {
        let d = self;
        let small = d.abs().lt(Lanes::splat(TURN_LIMIT));
        if !small.all() {
            return None;
        }
        let z = d * d;
        // sin δ = δ (1 − z/3! + z²/5! − z³/7!), cos δ − 1 = −z/2! + z²/4! − z³/6! + z⁴/8!
        let sd = d + d * z * z.poly(&TURN_SIN);
        let cm1 = z * z.poly(&TURN_COS);
        Some((sin + (sin * cm1 + cos * sd), cos + (cos * cm1 - sin * sd)))
    }

    /// `atan2(y, x)` per lane, branch-free: the angle of `(x, y)` in `[−π, π]`.
    ///
    /// `|y|/|x|` is reduced to `[0, 0.66]` (Cephes `atan.c`: `π/2 − atan(|x|/|y|)`
    /// above `tan 3π/8`, `π/4 + atan((|y| − |x|)/(|y| + |x|))` above 0.66) without
    /// forming the ratio first; then the Cephes rational approximation; then
    /// the quadrant. Within 2 ulp of `f64::atan2` for finite arguments (tested).
    #[inline(always)]
    pub fn atan2(y: Lanes<W>, x: Lanes<W>) -> Lanes<W> {
        let (ay, ax) = (y.abs(), x.abs());
        let big = ay.gt(ax * TAN_3PI_8);
        let mid = !big & ay.gt(ax * 0.66);
        let zero = Lanes::splat(0.0);
        let num = Lanes::select(big, -ax, Lanes::select(mid, ay - ax, ay));
        let den = Lanes::select(big, ay, Lanes::select(mid, ay + ax, ax));
        let base = Lanes::select(
            big,
            Lanes::splat(std::f64::consts::FRAC_PI_2),
            Lanes::select(mid, Lanes::splat(std::f64::consts::FRAC_PI_4), zero),
        );
        let more = Lanes::select(
            big,
            Lanes::splat(PIO2_LO),
            Lanes::select(mid, Lanes::splat(0.5 * PIO2_LO), zero),
        );
        // 0/0 (both arguments zero) is angle 0.
        let r = Lanes::select(den.eq_lanes(zero), zero, num / den);
        let z = r * r;
        let p = r * (z * z.poly(&ATAN_P) / z.poly(&ATAN_Q)) + r;
        let a = base + (p + more);
        // Left half-plane (sign bit of x set, −0 included): π − a, with π in
        // two parts; then the sign of y.
        let left = x.sign_mask();
        let a = Lanes::select(
            left,
            (Lanes::splat(std::f64::consts::PI) - a) + 2.0 * PIO2_LO,
            a,
        );
        a.copysign(y)
    }
}

#[cfg(test)]
mod tests;
