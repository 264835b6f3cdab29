//! Fixed-point and hardware-float helpers for the per-sample path (docs/numerics.md, "Per-sample
//! arithmetic on the M4F").
//!
//! The Cortex-M4F has single-precision floating point in hardware but no double precision: every
//! f64 operation is a software routine of 50–150 instructions. It does have single-cycle
//! 32×32 → 64-bit integer multiplies and 64-bit adds in two instructions, so the quantities that
//! need more than f32's 24 bits (E, c, a_i, the linearized output, all needed to ~1e-10
//! relative) are carried as i64 with a fixed binary point, and the small corrections stay f32.
//!
//! Formats: volts with [`VOLT_BITS`] fraction bits (±2048 V, 2.2e-16 V resolution: E below 2 V is
//! then under 2^53 and converts to f64 without rounding work), g with
//! [`G_BITS`] (±32768 g, 3.6e-15 g). A per-code factor carries 32 more fraction bits than its
//! product so that [`mul_code`] keeps ~2^-60 relative precision.
//!
//! Everything here is integer arithmetic or a correctly rounded IEEE-754 operation, so the host
//! and the firmware compute the same bits.

/// Fraction bits of a fixed-point voltage.
pub(crate) const VOLT_BITS: u32 = 52;
/// Fraction bits of a fixed-point acceleration in g.
pub(crate) const G_BITS: u32 = 48;
/// Extra fraction bits of a per-code factor over its product ([`mul_code`]).
pub(crate) const CODE_FACTOR_BITS: u32 = 32;
/// Fraction bits of the cheap f32 → fixed conversion: values below 2^-9 in magnitude convert
/// with one VMUL + one VCVT, truncated to 2^-40 (9.1e-13).
const F32_FRACTION_BITS: u32 = 40;

/// 2^n as f64 (exact for 0 ≤ n ≤ 1023).
#[inline]
const fn pow2(n: u32) -> f64 {
    f64::from_bits((1023 + n as u64) << 52)
}

/// `code · factor / 2^32`, rounded towards −∞: a 32-bit ADC code times a per-code factor with
/// [`CODE_FACTOR_BITS`] extra fraction bits. Two 32×32 → 64 multiplies, no overflow for any
/// code and factor (|result| < 2^62).
#[inline]
pub(crate) fn mul_code(code: i32, factor: i64) -> i64 {
    // factor = hi·2^32 + lo with lo unsigned: code·factor / 2^32 = code·hi + code·lo / 2^32,
    // and code·hi·2^32 is a multiple of 2^32, so only the second part needs the floor.
    let hi = (factor >> 32) as i32;
    let lo = factor as u32;
    i64::from(code) * i64::from(hi) + ((i64::from(code) * i64::from(lo)) >> 32)
}

/// f64 → fixed with `bits` (≤ 96) fraction bits, rounded to nearest (ties away from zero, like
/// `libm::round`); None when the value is not finite or |v|·2^bits ≥ 2^61 (so that four such
/// values cannot overflow a sum; the caller then takes the f64 path). Done on the bit pattern:
/// a soft-float multiply, round and conversion would cost ≈ 150 instructions on the M4F. Not
/// inlined: off the per-sample path it is called from a dozen places at activation (flash).
#[inline(never)]
pub(crate) fn from_f64(v: f64, bits: u32) -> Option<i64> {
    let pattern = v.to_bits();
    let biased = ((pattern >> 52) & 0x7FF) as i32;
    // |v|·2^bits = 1.m × 2^e (for normal v; zero and subnormals give e far below −1).
    let e = biased - 1023 + bits as i32;
    if e >= 61 {
        return None; // also ±∞ and NaN (biased = 2047)
    }
    if e < -1 {
        return Some(0); // below 1/2: rounds to 0
    }
    let mantissa = (pattern & ((1 << 52) - 1)) | (1 << 52);
    let magnitude = if e >= 52 {
        mantissa << (e - 52)
    } else {
        let shift = 52 - e; // 1..=53
        (mantissa + (1 << (shift - 1))) >> shift
    };
    // magnitude < 2^61: the cast and the negation are exact.
    let magnitude = magnitude as i64;
    Some(if pattern >> 63 != 0 {
        -magnitude
    } else {
        magnitude
    })
}

/// f32 → fixed with `bits` (≥ 40) fraction bits, truncated towards zero to 2^-40 when |v| < 2^-9
/// (the tilt correction, the root series' c·g, the linearized ΔE): one VMUL and one VCVT on the
/// M4F; larger values exactly. None when not finite or |v|·2^bits ≥ 2^61.
#[inline]
pub(crate) fn from_f32(v: f32, bits: u32) -> Option<i64> {
    // [`from_f32_truncated`] with the 2^-40 fast resolution. Beyond 2^-9 a 24-bit significand
    // times 2^bits (bits ≥ 40) is a whole number, so its exact conversion is also the rounded one.
    from_f32_truncated(v, F32_FRACTION_BITS, bits)
}

/// [`from_f32`] for a value the caller has bounded below 2^-9 in magnitude (from the table, at
/// activation): one VMUL and one VCVT, truncated to 2^-40, no range check. Outside that bound the
/// result would be wrong (VCVT saturates), so it is only for values bounded by construction.
#[inline]
pub(crate) fn from_f32_small(v: f32, bits: u32) -> i64 {
    i64::from((v * (pow2(F32_FRACTION_BITS) as f32)) as i32) << (bits - F32_FRACTION_BITS)
}

/// f32 → f64 (exact) on the bit pattern for normal numbers and zero: compiler-builtins'
/// `__aeabi_f2d` costs ≈ 14 instructions and a call; subnormals, ±∞ and NaN go through it.
#[inline]
pub(crate) fn f32_to_f64(v: f32) -> f64 {
    let bits = v.to_bits();
    let exponent = (bits >> 23) & 0xFF;
    if exponent == 0 || exponent == 0xFF {
        return if bits << 1 == 0 {
            f64::from_bits(u64::from(bits) << 32)
        } else {
            f64::from(v)
        };
    }
    // Rebias 127 → 1023 (+896) in the high word; 29 more fraction bits below.
    let high = (bits & 0x8000_0000) | (((bits & 0x7FFF_FFFF) >> 3) + (896 << 20));
    f64::from_bits((u64::from(high) << 32) | u64::from(bits << 29))
}

/// f32 → fixed with `bits` (≥ `fast_bits`) fraction bits, truncated towards zero to
/// 2^-`fast_bits` when |v| < 2^(31 − `fast_bits`) (one VMUL and one VCVT), exactly
/// ([`from_f32_exact`]) beyond. None when not finite or out of range.
#[inline]
pub(crate) fn from_f32_truncated(v: f32, fast_bits: u32, bits: u32) -> Option<i64> {
    // Both powers of two are exact in f32; the comparison also refuses NaN.
    let scaled = v * (pow2(fast_bits) as f32);
    if scaled.abs() < 2_147_483_648.0 {
        Some(i64::from(scaled as i32) << (bits - fast_bits))
    } else {
        from_f32_exact(v, bits)
    }
}

/// Fixed (`bits` ≤ 64 fraction bits) → f64, correctly rounded (to nearest, ties to even: the
/// bits of `raw as f64 / 2^bits`). Integer operations only: compiler-builtins' i64 → f64
/// conversion costs ≈ 42 instructions on the M4F, and the per-sample path makes five. For
/// 2^32 ≤ |raw| < 2^53 (E, a_i, T, R and the linearized output on that path) the conversion is
/// exact and takes ≈ 20 instructions on 32-bit words; the scale by 2^-bits goes straight into the
/// exponent field.
#[inline]
pub(crate) fn to_f64(raw: i64, bits: u32) -> f64 {
    let sign = ((raw as u64) >> 32) as u32 & 0x8000_0000;
    let magnitude = raw.unsigned_abs();
    let (high, low) = ((magnitude >> 32) as u32, magnitude as u32);
    let zeros = high.leading_zeros();
    if (11..32).contains(&zeros) {
        // The leading one (bit 63 − zeros) moves to bit 20 of the high word, the significand's
        // hidden bit; it adds one to the exponent field, hence the − 1 there. Biased exponent
        // 1023 + 63 − zeros − bits ≥ 1023 − 64 > 0: always normal.
        let shift = zeros - 11; // 0..=20
        let top = (high << shift) | ((low >> 1) >> (31 - shift));
        let exponent_field = 1023 + 63 - 1 - zeros - bits;
        let top = sign | ((exponent_field << 20) + top);
        return f64::from_bits((u64::from(top) << 32) | u64::from(low << shift));
    }
    to_f64_rounded(raw, bits)
}

/// [`to_f64`] for |raw| < 2^32 or ≥ 2^53 (with rounding to nearest, ties to even). Not inlined:
/// five call sites on the per-sample path, and the fast case above is the common one (flash).
#[inline(never)]
fn to_f64_rounded(raw: i64, bits: u32) -> f64 {
    if raw == 0 {
        return 0.0;
    }
    let sign = (raw as u64) & (1 << 63);
    let magnitude = raw.unsigned_abs();
    let zeros = magnitude.leading_zeros();
    let exponent_field = u64::from(1023 + 63 - 1 - zeros - bits);
    let significand = if zeros >= 11 {
        magnitude << (zeros - 11)
    } else {
        let shift = 11 - zeros; // 1..=11 bits rounded off
        let kept = magnitude >> shift;
        let rest = magnitude & ((1 << shift) - 1);
        let half = 1 << (shift - 1);
        // A carry into bit 53 moves the exponent up by one through the addition below.
        kept + u64::from(rest > half || (rest == half && kept & 1 != 0))
    };
    f64::from_bits(sign | ((exponent_field << 52) + significand))
}

/// Fixed (`bits`, 32 ≤ bits ≤ 150) → f32 from its two 32-bit halves: two VCVTs and a VMLA,
/// no branch. Error ≤ 2 roundings (2u·|value|) plus the 8 low bits dropped (2^(8 − bits)).
#[inline]
pub(crate) fn to_f32(raw: i64, bits: u32) -> f32 {
    let high = (raw >> 32) as i32 as f32;
    let low = ((raw as u32) >> 8) as f32;
    // Both scales are powers of two, exact in f32 for these `bits`.
    high * ((pow2(32) / pow2(bits)) as f32) + low * ((pow2(8) / pow2(bits)) as f32)
}

/// `x.is_finite()` on the bit pattern: core's version is a float comparison, a soft-float call
/// (≈ 20–40 instructions) on the M4F, and the per-sample path checks a handful of values. LLVM
/// recognises a masked compare of the pattern as a floating-point class test and turns it back
/// into soft-float comparisons (`__aeabi_dcmpeq` + `__aeabi_dcmpun`, ≈ 45 instructions); the
/// exponent field shifted down to a byte-aligned u32 is not matched (checked in the ELF).
#[inline]
pub(crate) fn is_finite(x: f64) -> bool {
    ((x.to_bits() >> 52) as u32 & 0x7FF) != 0x7FF
}

/// ⌊a·b / 2^64⌋, the high half of the signed 128-bit product: four 32×32 → 64 multiplies (a
/// 128-bit multiply is a library call on the M4F). Two fixed-point values with fa and fb fraction
/// bits give a product with fa + fb − 64.
#[inline]
pub(crate) fn mul_hi(a: i64, b: i64) -> i64 {
    // a = ah·2^32 + al with al unsigned (the same for b); no partial sum below can overflow:
    // |ah·bl| + 2^32 ≤ (2^31)(2^32 − 1) + 2^32 < 2^63.
    let (ah, al) = (a >> 32, a & 0xFFFF_FFFF);
    let (bh, bl) = (b >> 32, b & 0xFFFF_FFFF);
    let low = ((al as u64) * (bl as u64)) >> 32;
    let mid1 = ah * bl + low as i64;
    let mid2 = al * bh + (mid1 & 0xFFFF_FFFF);
    ah * bh + (mid1 >> 32) + (mid2 >> 32)
}

/// f32 → fixed with `bits` fraction bits from the bit pattern: exact when v is a multiple of
/// 2^-bits, else truncated towards zero (error < 2^-bits); integer operations only. None when v
/// is not finite or |v|·2^bits ≥ 2^61. Not inlined: the slow side of [`from_f32_truncated`].
#[inline(never)]
pub(crate) fn from_f32_exact(v: f32, bits: u32) -> Option<i64> {
    let pattern = v.to_bits();
    let biased = ((pattern >> 23) & 0xFF) as i32;
    if biased == 0 {
        return Some(0); // zero, or a subnormal (< 2^-126): below 2^-bits for any bits ≤ 100
    }
    // |v|·2^bits = m·2^shift with the 24-bit significand m.
    let shift = biased - 150 + bits as i32;
    if shift > 61 - 24 {
        return None; // also ±∞ and NaN (biased = 255)
    }
    let significand = i64::from((pattern & 0x7F_FFFF) | 0x80_0000);
    let magnitude = if shift >= 0 {
        significand << shift
    } else if shift > -24 {
        significand >> -shift
    } else {
        0
    };
    Some(if pattern >> 31 != 0 {
        -magnitude
    } else {
        magnitude
    })
}

/// `x.is_nan()` on the bit pattern (exponent all ones, fraction non-zero).
#[inline]
pub(crate) fn is_nan(x: f64) -> bool {
    x.to_bits() & 0x7FFF_FFFF_FFFF_FFFF > 0x7FF0_0000_0000_0000
}

/// √x in single precision, correctly rounded (IEEE 754): the FPU's VSQRT on the M4F (`libm`'s
/// `sqrtf` is a software routine there, and `core` has no `f32::sqrt`), `libm::sqrtf` (also
/// correctly rounded, hence the same bits) elsewhere.
#[inline]
pub(crate) fn sqrt_f32(x: f32) -> f32 {
    #[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
    {
        let bits: u32;
        // The `sreg` operand class needs the `vfp2` feature, which this target (single-precision
        // FPU only) does not enable; the value goes through a core register and S15 instead.
        // SAFETY: VMOV/VSQRT.F32 touch one core register in, one out and S15 (declared
        // clobbered); no memory, no stack, no flags other than the FPSCR exception bits (which
        // nothing here reads).
        #[allow(unsafe_code)]
        unsafe {
            core::arch::asm!(
                "vmov s15, {x}",
                "vsqrt.f32 s15, s15",
                "vmov {root}, s15",
                x = in(reg) x.to_bits(),
                root = lateout(reg) bits,
                out("s15") _,
                options(pure, nomem, nostack, preserves_flags),
            );
        }
        f32::from_bits(bits)
    }
    #[cfg(not(all(target_arch = "arm", target_abi = "eabihf")))]
    {
        libm::sqrtf(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator (xorshift64*), so the sweeps are reproducible.
    fn numbers(seed: u64) -> impl Iterator<Item = u64> {
        let mut s = seed;
        core::iter::from_fn(move || {
            s ^= s >> 12;
            s ^= s << 25;
            s ^= s >> 27;
            Some(s.wrapping_mul(0x2545_F491_4F6C_DD1D))
        })
    }

    #[test]
    fn mul_code_is_the_floor_of_the_exact_96_bit_product() {
        for (a, b) in numbers(7).zip(numbers(99)).take(200_000) {
            let code = a as i32;
            let factor = (b as i64) >> (b % 40);
            let exact = (i128::from(code) * i128::from(factor)) >> 32;
            assert_eq!(i128::from(mul_code(code, factor)), exact, "{code} {factor}");
        }
        for code in [i32::MIN, i32::MAX, -1, 0, 1] {
            for factor in [i64::MIN, i64::MAX, -1, 0, 1, 1 << 32, -(1 << 32)] {
                let exact = (i128::from(code) * i128::from(factor)) >> 32;
                assert_eq!(i128::from(mul_code(code, factor)), exact);
            }
        }
    }

    #[test]
    fn to_f64_rounds_like_the_exact_scaled_conversion() {
        for a in numbers(3).take(200_000) {
            let raw = (a as i64) >> (a % 63);
            for bits in [G_BITS, VOLT_BITS] {
                // i64 → f64 rounds once; the power-of-two scale is exact: the reference.
                let want = raw as f64 * pow2(bits).recip();
                assert_eq!(to_f64(raw, bits).to_bits(), want.to_bits(), "{raw}");
            }
        }
        assert_eq!(to_f64(0, G_BITS).to_bits(), 0.0f64.to_bits());
        assert_eq!(to_f64(i64::MIN, VOLT_BITS), -2048.0);
    }

    #[test]
    fn from_f32_truncates_to_2_pow_minus_40_on_both_paths() {
        for a in numbers(11).take(100_000) {
            let v = f32::from_bits((a as u32) & 0xBFFF_FFFF); // |v| < 2 (exponent bit 30 clear)
            if !v.is_finite() {
                continue;
            }
            for bits in [G_BITS, VOLT_BITS] {
                let got = from_f32(v, bits).unwrap();
                let err = to_f64(got, bits) - f64::from(v);
                assert!(err.abs() < pow2(40).recip(), "{v:e}: {err:e}");
                // Beyond 2^-9 the value is a whole number of 2^-bits: rounded through f64 alike.
                if f64::from(v).abs() >= pow2(9).recip() {
                    assert_eq!(Some(got), from_f64(f64::from(v), bits), "{v:e}");
                }
            }
        }
        assert_eq!(from_f32(f32::NAN, G_BITS), None);
        assert_eq!(from_f32(f32::INFINITY, G_BITS), None);
        assert_eq!(from_f32(-1.5, G_BITS), Some(-3 << (G_BITS - 1)));
    }

    #[test]
    fn from_f32_truncated_is_within_its_fast_resolution_and_exact_beyond() {
        for a in numbers(43).take(100_000) {
            let v = f32::from_bits((a as u32) & 0xC3FF_FFFF); // |v| < 2^8
            if !v.is_finite() {
                continue;
            }
            let got = to_f64(from_f32_truncated(v, 26, 40).unwrap(), 40);
            let exact = f64::from(v);
            if exact.abs() < 32.0 {
                assert!((got - exact).abs() < pow2(26).recip(), "{v:e}");
                assert!(got.abs() <= exact.abs(), "towards zero: {v:e}");
            } else {
                assert_eq!(got, exact, "{v:e}");
            }
        }
        assert_eq!(from_f32_truncated(f32::NAN, 26, 40), None);
    }

    #[test]
    fn f32_to_f64_is_the_exact_widening_for_every_class() {
        for a in numbers(47).take(200_000) {
            let v = f32::from_bits(a as u32);
            let got = f32_to_f64(v);
            if v.is_nan() {
                assert!(got.is_nan());
            } else {
                assert_eq!(got.to_bits(), f64::from(v).to_bits(), "{v:e}");
            }
        }
        for v in [
            0.0f32,
            -0.0,
            f32::MIN_POSITIVE,
            1e-40,
            f32::MAX,
            f32::INFINITY,
            -1.5,
        ] {
            assert_eq!(f32_to_f64(v).to_bits(), f64::from(v).to_bits(), "{v:e}");
        }
    }

    #[test]
    fn from_f32_small_truncates_to_2_pow_minus_40_below_2_pow_minus_9() {
        for a in numbers(53).take(100_000) {
            let v = f32::from_bits(a as u32);
            if v.is_nan() || v.abs() >= 1.0 / 512.0 {
                continue;
            }
            let got = to_f64(from_f32_small(v, G_BITS), G_BITS);
            assert!((got - f64::from(v)).abs() < pow2(40).recip(), "{v:e}");
        }
    }

    #[test]
    fn from_f64_is_the_rounded_scaled_value() {
        for a in numbers(23).take(200_000) {
            // Magnitudes from 2^-70 to 2^20, both signs.
            let exponent = (a % 91) as i32 - 70;
            let v = f64::from_bits((a >> 12) | (((1023 + exponent) as u64) << 52));
            let v = if a & 1 == 0 { v } else { -v };
            for bits in [G_BITS, VOLT_BITS, G_BITS + CODE_FACTOR_BITS] {
                let scaled = v * pow2(bits);
                let want = (libm::fabs(scaled) < pow2(61)).then(|| libm::round(scaled) as i64);
                assert_eq!(from_f64(v, bits), want, "{v:e} bits {bits}");
            }
        }
        assert_eq!(from_f64(0.0, G_BITS), Some(0));
        assert_eq!(from_f64(-0.0, G_BITS), Some(0));
        assert_eq!(from_f64(f64::MIN_POSITIVE / 4.0, G_BITS), Some(0));
    }

    #[test]
    fn from_f64_rounds_to_nearest_and_refuses_what_would_overflow_a_sum() {
        assert_eq!(from_f64(1.5, G_BITS), Some(3 << (G_BITS - 1)));
        assert_eq!(from_f64(pow2(G_BITS).recip() * 0.49, G_BITS), Some(0));
        assert_eq!(from_f64(pow2(G_BITS).recip() * 0.51, G_BITS), Some(1));
        assert_eq!(from_f64(8192.0, G_BITS), None);
        assert!(from_f64(8191.0, G_BITS).is_some());
        assert_eq!(from_f64(f64::NAN, G_BITS), None);
        assert_eq!(from_f64(-f64::INFINITY, VOLT_BITS), None);
    }

    #[test]
    fn to_f32_is_within_two_roundings_and_the_dropped_low_bits() {
        for a in numbers(5).take(100_000) {
            let raw = (a as i64) >> (a % 50);
            for bits in [G_BITS, VOLT_BITS] {
                let v = to_f32(raw, bits);
                let exact = to_f64(raw, bits);
                let bound = 2.0 * exact.abs() * 2f64.powi(-24) + pow2(bits - 8).recip();
                assert!((f64::from(v) - exact).abs() <= bound, "{raw}");
            }
        }
        assert_eq!(to_f32(200 << G_BITS, G_BITS), 200.0);
        assert_eq!(to_f32(-3 << (G_BITS - 2), G_BITS), -0.75);
    }

    #[test]
    fn to_f64_is_the_correctly_rounded_conversion_for_every_scale() {
        for a in numbers(41).take(200_000) {
            let raw = (a as i64) >> (a % 64);
            let bits = (a >> 8) as u32 % 65;
            let want = raw as f64 * pow2(bits).recip();
            assert_eq!(to_f64(raw, bits).to_bits(), want.to_bits(), "{raw} {bits}");
        }
        // Ties to even, and a carry out of the significand.
        for raw in [
            i64::MAX,
            i64::MIN,
            (1 << 53) + 1,
            (1 << 54) + 2,
            (1 << 54) + 6,
            -((1 << 53) + 1),
            (1 << 53) - 1,
            1,
            -1,
        ] {
            assert_eq!(to_f64(raw, 0).to_bits(), (raw as f64).to_bits(), "{raw}");
        }
    }

    #[test]
    fn mul_hi_is_the_floor_of_the_exact_128_bit_product() {
        for (a, b) in numbers(13).zip(numbers(71)).take(200_000) {
            let x = (a as i64) >> (a % 63);
            let y = (b as i64) >> (b % 63);
            let exact = (i128::from(x) * i128::from(y)) >> 64;
            assert_eq!(i128::from(mul_hi(x, y)), exact, "{x} {y}");
        }
        // Every pair of the extremes and the 32-bit word edges.
        let edges = [
            i64::MIN,
            i64::MAX,
            -1,
            0,
            1,
            1 << 32,
            -(1 << 32),
            u32::MAX as i64,
        ];
        for x in edges {
            for y in edges {
                let exact = (i128::from(x) * i128::from(y)) >> 64;
                assert_eq!(i128::from(mul_hi(x, y)), exact, "{x} {y}");
            }
        }
    }

    #[test]
    fn from_f32_exact_is_the_scaled_value_truncated_towards_zero() {
        for a in numbers(37).take(200_000) {
            let v = f32::from_bits(a as u32);
            for bits in [24, 40, 62] {
                let got = from_f32_exact(v, bits);
                let scaled = f64::from(v) * pow2(bits);
                if !v.is_finite() || scaled.abs() >= pow2(61) {
                    assert_eq!(got, None, "{v:e}");
                } else {
                    assert_eq!(got, Some(scaled.trunc() as i64), "{v:e} bits {bits}");
                }
            }
        }
        assert_eq!(from_f32_exact(-0.0, 40), Some(0));
        assert_eq!(from_f32_exact(0.75, 2), Some(3));
        assert_eq!(from_f32_exact(-0.75, 1), Some(-1));
    }

    #[test]
    fn the_bit_tests_agree_with_core_on_every_class_of_f64() {
        let specials = [
            0.0,
            -0.0,
            1.5,
            -2.0e300,
            f64::MIN_POSITIVE / 8.0,
            f64::MAX,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            -f64::NAN,
            f64::from_bits(0x7FF0_0000_0000_0001),
            f64::from_bits(0xFFF8_0000_0000_0000),
        ];
        let random = numbers(29).take(100_000).map(f64::from_bits);
        for x in specials.into_iter().chain(random) {
            assert_eq!(is_finite(x), x.is_finite(), "{:#x}", x.to_bits());
            assert_eq!(is_nan(x), x.is_nan(), "{:#x}", x.to_bits());
        }
    }

    #[test]
    fn sqrt_f32_is_the_correctly_rounded_root() {
        for a in numbers(17).take(100_000) {
            let x = f32::from_bits((a as u32) & 0x7FFF_FFFF);
            if !x.is_finite() {
                continue;
            }
            assert_eq!(sqrt_f32(x).to_bits(), x.sqrt().to_bits(), "{x:e}");
        }
    }
}
