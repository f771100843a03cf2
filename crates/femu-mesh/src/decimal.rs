//! Decimal text of `f64` values for result files: the shortest digits that read back to the
//! same value (full double precision), fast (ryu), in the notation of Rust's `{:?}`.

/// Whether the two shortest round-trip digit strings of `v` can be equally close to it (a tie,
/// which ryu breaks to even and Rust's formatter upwards). A tie needs the exact decimal value of
/// `v` to end one digit after the shortest string, so to have at most 18 significant digits
/// (shortest strings have at most 17). With `v = m 2^e`, `m` odd, the exact value is an odd
/// integer when `e = 0` (its last digit is never a tie against a coarser ulp), even when
/// `e > 0` (a trailing 5 at the k-th digit would need fewer factors of 2 than the ulp has), and
/// `m 5^-e / 10^-e` when `e < 0`, whose significant digits are those of `m 5^-e`. So only
/// `e < 0` with `m 5^-e < 10^18` can tie: dyadic values with few binary digits, e.g. `X.25`
/// near 1e15; never the full-mantissa results of a computation in practice.
fn may_tie(v: f64) -> bool {
    let bits = v.to_bits();
    let biased = ((bits >> 52) & 0x7ff) as i64;
    let fraction = bits & ((1u64 << 52) - 1);
    let (mut m, mut e) = if biased == 0 {
        (fraction, -1074)
    } else {
        (fraction | (1u64 << 52), biased - 1075)
    };
    if m == 0 {
        return false;
    }
    let tz = m.trailing_zeros();
    m >>= tz;
    e += i64::from(tz);
    e < 0 && -e <= 26 && u128::from(m) * 5u128.pow((-e) as u32) < 1_000_000_000_000_000_000
}

/// Appends `v` exactly as `format!("{v:?}")` would: the shortest digits that round-trip
/// (ryu and Rust's formatter both produce the shortest, closest-to-exact digit string; the rare
/// values where they could differ, see [`may_tie`], go through `{:?}`), in decimal notation
/// with at least one fractional digit for `1e-4 ≤ |v| < 1e16` and zero, and as `de-5` /
/// `d.ddde-5` (no `+`, no padding) otherwise. ryu's notation matches Rust's except for
/// `1e-5 ≤ |v| < 1e-4`, which ryu writes as `0.0000ddd` and is rewritten here. Non-finite
/// values (never written: callers that write files refuse them) go through `{:?}` too.
pub fn push_f64(buf: &mut Vec<u8>, v: f64, ryu: &mut ryu::Buffer) {
    if !v.is_finite() || may_tie(v) {
        buf.extend_from_slice(format!("{v:?}").as_bytes());
        return;
    }
    let s = ryu.format_finite(v).as_bytes();
    let (sign, digits) = match s.split_first() {
        Some((b'-', rest)) => (&s[..1], rest),
        _ => (&s[..0], s),
    };
    match digits.strip_prefix(b"0.0000") {
        Some(d) if !d.is_empty() && d[0] != b'0' => {
            buf.extend_from_slice(sign);
            buf.push(d[0]);
            if d.len() > 1 {
                buf.push(b'.');
                buf.extend_from_slice(&d[1..]);
            }
            buf.extend_from_slice(b"e-5");
        }
        _ => buf.extend_from_slice(s),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `push_f64` writes the bytes of `{:?}`: random bit patterns (every exponent), random
    /// values around each power of ten (both sides of the notation switches at 1e-5, 1e-4 and
    /// 1e16), and special cases.
    #[test]
    fn floats_are_written_as_debug_formatting() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let mut values = vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            1e-5,
            1e-4,
            9.999999999999999e-5,
            f64::from_bits(1e-5f64.to_bits() + 1),
            9.99999999999e-6,
            1e16,
            9999999999999998.0,
            1e15,
            f64::MIN_POSITIVE,
            5e-324,
            f64::MAX,
            f64::EPSILON,
            0.1 + 0.2,
        ];
        for _ in 0..200_000 {
            values.push(f64::from_bits(next()));
        }
        for e in -30..=30 {
            for _ in 0..2_000 {
                let m = (next() >> 11) as f64 / (1u64 << 53) as f64 * 10.0;
                values.push(m * 10f64.powi(e));
                values.push(-m * 10f64.powi(e));
            }
        }
        // Dyadic values with few binary digits (the candidates for ties) at every scale.
        for j in 0..=60 {
            for _ in 0..1_000 {
                let k = (next() >> (11 + (next() % 40))) | 1;
                values.push(k as f64 / (1u64 << j) as f64);
            }
        }
        values.push(1658206780088562.0 + 0.25); // exactly representable: a tie
        let mut ryu = ryu::Buffer::new();
        let mut buf = Vec::new();
        for v in values.into_iter().filter(|v| v.is_finite()) {
            buf.clear();
            push_f64(&mut buf, v, &mut ryu);
            assert_eq!(
                std::str::from_utf8(&buf).unwrap(),
                format!("{v:?}"),
                "{v:e}"
            );
        }
    }
}
