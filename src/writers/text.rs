//! Text of numbers for the writers, fast and without allocation, byte for byte the text of the
//! standard formats the files have always used (`{}`, `{:?}`, `{:e}`, `{:.12e}` of an `f64`), and
//! [`write_items`], which formats a long list of items in blocks on every core and writes the
//! blocks in order, so a writer streams a file of any size with a few megabytes of buffers and
//! the same bytes whatever the thread count.
//!
//! # Why not `format!`
//! A 10-million-hex mesh writes some 10^8 numbers per format. `format!` allocates a `String` per
//! call and std's float printing (Grisu with a Dragon fallback) is several times slower than
//! zmij's (Schubfach). Both find the same digits: the shortest decimal that reads back to the
//! same `f64`, the closest to it among those (the unit tests compare them on random numbers of
//! every magnitude) but for a binary value exactly halfway between two shortest candidates, which
//! std rounds up and zmij to even: those (found exactly), NaN and infinities go to std. This
//! module only lays the digits out as each std format does.
//!
//! `{:.12e}` (13 significant digits, correctly rounded) is derived from the shortest digits D:
//! with at most 13 digits, D padded with zeros is the answer (the binary value lies within half
//! an ulp of D, far from a 13-digit rounding boundary); with 15 or more, rounding D to 13 digits
//! rounds the binary value alike (a 14-digit midpoint between the two would itself be a shorter
//! candidate in the round-trip interval); with exactly 14 digits ending in 5, D may be that
//! midpoint and the binary value decides, so std's own formatting is asked (as for subnormals,
//! whose precision is below 13 digits).

use rayon::prelude::*;
use std::io::{self, Write};

/// A growing text buffer with number formatting.
#[derive(Default)]
pub struct Text {
    pub bytes: Vec<u8>,
}

/// The shortest round-trip digits of a finite `f64`: value = d1.d2...dn x 10^exp, the n digits
/// being those of `digits` (n >= 1, no trailing zero; zero has the single digit 0).
struct Shortest {
    negative: bool,
    digits: u64,
    n: u32,
    exp: i32,
}

impl Shortest {
    /// zmij's digits, or `None` where std's may differ: NaN and infinities, and a binary value
    /// exactly halfway between two shortest candidates (std takes the larger, zmij the even one;
    /// such values have a short exact decimal expansion, e.g. 1 + 2^-17 = 1.00000762939453125).
    fn of(x: f64) -> Option<Shortest> {
        if !x.is_finite() {
            return None;
        }
        let out = Shortest::parse(zmij::Buffer::new().format_finite(x).as_bytes());
        (!out.halfway_from_a_neighbour(x.abs())).then_some(out)
    }

    /// The digits of zmij's text, `[-]int.frac` or `[-]d[.ddd]e[-]k`: the digit characters read
    /// as one integer (at most 17 significant digits and a few zeros: it fits), trailing zeros
    /// dropped, the exponent from the count of fraction digits. One pass without a branch per
    /// character: the loop that looked for the point and the first significant digit was a
    /// tenth of the writers' time.
    fn parse(s: &[u8]) -> Shortest {
        let negative = s[0] == b'-';
        let s = &s[negative as usize..];
        // An exponent has at most three digits and a sign: the `e` is among the last five bytes.
        let tail = s.len().saturating_sub(5);
        let (mantissa, exp10) = match s[tail..].iter().position(|&c| c == b'e') {
            Some(k) => (&s[..tail + k], exponent(&s[tail + k + 1..])),
            None => (s, 0),
        };
        let (mut digits, mut count, mut point) = (0u64, 0i32, None);
        for &c in mantissa {
            let d = c.wrapping_sub(b'0');
            if d < 10 {
                digits = 10 * digits + d as u64;
                count += 1;
            } else {
                point = Some(count);
            }
        }
        if digits == 0 {
            return Shortest { negative, digits: 0, n: 1, exp: 0 };
        }
        let mut fraction_digits = count - point.unwrap_or(count);
        while digits % 10 == 0 {
            digits /= 10;
            fraction_digits -= 1;
        }
        let n = decimal_len(digits);
        Shortest { negative, digits, n, exp: n as i32 - 1 - fraction_digits + exp10 }
    }

    /// Whether `x` (>= 0) is exactly the digits plus or minus half a unit of their last place.
    fn halfway_from_a_neighbour(&self, x: f64) -> bool {
        if !short_exact_expansion(x) {
            return false;
        }
        let last_place = self.exp - (self.n as i32 - 1);
        [10 * self.digits + 5, 10 * self.digits - 5].into_iter().any(|m| decimal_is(x, m, last_place - 1))
    }
}

/// Whether the exact decimal expansion of `x` (>= 0) may have 18 significant digits or fewer,
/// the most a value halfway between two candidates of at most 17 digits has. A value with k
/// bits after the point and odd significand m has about log10(m) + k log10(5) digits; most
/// coordinates have some forty, and are decided here without arithmetic on their digits.
fn short_exact_expansion(x: f64) -> bool {
    let bits = x.to_bits();
    let biased = ((bits >> 52) & 0x7ff) as i32;
    let mut m = bits & ((1u64 << 52) - 1);
    let mut e = biased - 1075;
    if biased == 0 {
        e = -1074;
    } else {
        m |= 1 << 52;
    }
    if m == 0 {
        return false;
    }
    let zeros = m.trailing_zeros() as i32;
    let (m, fraction_bits) = (m >> zeros, -(e + zeros));
    if fraction_bits <= 0 {
        return x >= 1e17; // an integer: only one of more than 17 digits can lie halfway
    }
    let digits = (64 - m.leading_zeros()) as f64 * std::f64::consts::LOG10_2 + fraction_bits as f64 * 0.69897;
    digits < 19.5
}

/// The exponent after zmij's `e`: `[-+]digits`.
fn exponent(t: &[u8]) -> i32 {
    let (sign, t) = match t.first() {
        Some(b'-') => (-1, &t[1..]),
        Some(b'+') => (1, &t[1..]),
        _ => (1, t),
    };
    sign * t.iter().fold(0, |e, d| 10 * e + (d - b'0') as i32)
}

/// The number of decimal digits of `x` (1 for 0).
fn decimal_len(x: u64) -> u32 {
    x.checked_ilog10().unwrap_or(0) + 1
}

/// The two digits of 0 to 99.
const PAIRS: &[u8; 200] =
    b"0001020304050607080910111213141516171819202122232425262728293031323334353637383940414243444546474849\
5051525354555657585960616263646566676869707172737475767778798081828384858687888990919293949596979899";

/// The two digits of `pair` (< 100) at the start of `out`.
fn put_pair(out: &mut [std::mem::MaybeUninit<u8>], pair: u32) {
    let at = 2 * pair as usize;
    out[0].write(PAIRS[at]);
    out[1].write(PAIRS[at + 1]);
}

/// Whether the binary value `x` (>= 0) is exactly m x 10^p.
fn decimal_is(x: f64, m: u64, p: i32) -> bool {
    if p >= 0 {
        let exact = 10u128.checked_pow(p as u32).and_then(|t| t.checked_mul(m as u128));
        return match exact {
            Some(v) => x.fract() == 0.0 && x < 2f64.powi(127) && x as u128 == v,
            None => true, // beyond u128: not decided here, std formats it
        };
    }
    // m x 10^p = (m / 5^j) x 2^-j with j = -p: dyadic only when 5^j divides m.
    let j = -p as u32;
    let Some(five) = 5u64.checked_pow(j) else { return false };
    if !m.is_multiple_of(five) {
        return false;
    }
    let y = m / five;
    let yf = y as f64;
    yf as u64 == y && yf * 2f64.powi(-(j as i32)) == x
}

impl Text {
    pub fn with_capacity(n: usize) -> Self {
        Text { bytes: Vec::with_capacity(n) }
    }
    pub fn len(&self) -> usize {
        self.bytes.len()
    }
    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }
    pub fn clear(&mut self) {
        self.bytes.clear();
    }
    pub fn str(&mut self, s: &str) -> &mut Self {
        self.bytes.extend_from_slice(s.as_bytes());
        self
    }
    pub fn byte(&mut self, b: u8) -> &mut Self {
        self.bytes.push(b);
        self
    }
    /// An unsigned integer (`{}`).
    pub fn uint(&mut self, x: u64) -> &mut Self {
        self.digits(x, decimal_len(x));
        self
    }
    /// Integers separated by `sep`.
    pub fn uints(&mut self, xs: impl IntoIterator<Item = u64>, sep: &str) -> &mut Self {
        for (i, x) in xs.into_iter().enumerate() {
            if i > 0 {
                self.str(sep);
            }
            self.uint(x);
        }
        self
    }

    /// The n digits of `digits` (< 10^n; leading zeros written when it has fewer) straight into
    /// the buffer: through a digit buffer and a copy, each number cost a call to memmove, a tenth
    /// of the writers' time. Eight digits at a time in 32 bits, their four pairs independent of
    /// one another, rather than one chain of 64-bit divisions.
    fn digits(&mut self, mut digits: u64, n: u32) {
        debug_assert!(digits.checked_ilog10().is_none_or(|l| l < n));
        let (start, n) = (self.bytes.len(), n as usize);
        self.bytes.reserve(n);
        let out = &mut self.bytes.spare_capacity_mut()[..n];
        let mut i = n;
        while i >= 8 {
            let low = (digits % 100_000_000) as u32;
            digits /= 100_000_000;
            let (high, low) = (low / 10_000, low % 10_000);
            for (k, pair) in [high / 100, high % 100, low / 100, low % 100].into_iter().enumerate() {
                put_pair(&mut out[i - 8 + 2 * k..], pair);
            }
            i -= 8;
        }
        let mut rest = digits as u32;
        while i >= 2 {
            put_pair(&mut out[i - 2..], rest % 100);
            rest /= 100;
            i -= 2;
        }
        if i == 1 {
            out[0].write(b'0' + rest as u8);
        }
        // SAFETY: the n bytes after the length are initialised just above.
        unsafe { self.bytes.set_len(start + n) };
    }
    fn sign(&mut self, s: &Shortest) {
        if s.negative {
            self.bytes.push(b'-');
        }
    }
    /// d1.d2...dn e k of n digits, without the sign.
    fn exponential(&mut self, digits: u64, n: u32, exp: i32) {
        let tail = 10u64.pow(n - 1);
        self.digits(digits / tail, 1);
        if n > 1 {
            self.bytes.push(b'.');
            self.digits(digits % tail, n - 1);
        }
        self.bytes.push(b'e');
        if exp < 0 {
            self.bytes.push(b'-');
        }
        self.uint(exp.unsigned_abs() as u64);
    }
    /// Positional notation of the shortest digits, without the sign; `min_fraction` 1 writes
    /// `.0` after an integer.
    fn positional(&mut self, s: &Shortest, min_fraction: usize) {
        if s.exp < 0 {
            self.bytes.extend_from_slice(b"0.");
            self.bytes.extend(std::iter::repeat_n(b'0', (-s.exp - 1) as usize));
            self.digits(s.digits, s.n);
            return;
        }
        let whole = s.exp as u32 + 1;
        if s.n <= whole {
            self.digits(s.digits, s.n);
            self.bytes.extend(std::iter::repeat_n(b'0', (whole - s.n) as usize));
            if min_fraction > 0 {
                self.bytes.extend_from_slice(b".0");
            }
        } else {
            let tail = 10u64.pow(s.n - whole);
            self.digits(s.digits / tail, whole);
            self.bytes.push(b'.');
            self.digits(s.digits % tail, s.n - whole);
        }
    }

    /// Appends zmij's text of `x` where it is std's positional text as it stands, and says whether
    /// it did: in [1e-4, 1e16) both write the shortest digits positionally with `.0` after an
    /// integer (`{:?}`; `{}` without it: `point_zero` false), unless `x` may lie halfway between
    /// two candidates (rare, decided by [`Shortest::of`]). Copied as they stand, the digits are
    /// neither read back nor laid out again.
    fn as_zmij_writes(&mut self, x: f64, point_zero: bool) -> bool {
        let a = x.abs();
        if !(1e-4..1e16).contains(&a) || short_exact_expansion(a) {
            return false;
        }
        let mut buffer = zmij::Buffer::new();
        let text = buffer.format_finite(x);
        self.str(if point_zero { text } else { text.strip_suffix(".0").unwrap_or(text) });
        true
    }

    /// `format!("{x}")`.
    pub fn display(&mut self, x: f64) -> &mut Self {
        if self.as_zmij_writes(x, false) {
            return self;
        }
        let Some(s) = Shortest::of(x) else {
            return self.fallback(format_args!("{x}"));
        };
        self.sign(&s);
        self.positional(&s, 0);
        self
    }
    /// `format!("{x:?}")`.
    pub fn debug(&mut self, x: f64) -> &mut Self {
        if self.as_zmij_writes(x, true) {
            return self;
        }
        let Some(s) = Shortest::of(x) else {
            return self.fallback(format_args!("{x:?}"));
        };
        self.sign(&s);
        let a = x.abs();
        if a != 0.0 && !(1e-4..1e16).contains(&a) {
            self.exponential(s.digits, s.n, s.exp);
        } else {
            self.positional(&s, 1);
        }
        self
    }
    /// `format!("{x:e}")`.
    pub fn exp(&mut self, x: f64) -> &mut Self {
        let Some(s) = Shortest::of(x) else {
            return self.fallback(format_args!("{x:e}"));
        };
        self.sign(&s);
        self.exponential(s.digits, s.n, s.exp);
        self
    }
    /// `format!("{x:.12e}")`: 13 significant digits, correctly rounded (see the module notes).
    pub fn exp12(&mut self, x: f64) -> &mut Self {
        // Subnormals carry fewer than 13 significant digits: the shortest digits say too little.
        if x != 0.0 && x.abs() < f64::MIN_POSITIVE {
            return self.fallback(format_args!("{x:.12e}"));
        }
        let Some(s) = Shortest::of(x).filter(|s| !(s.n == 14 && s.digits % 10 == 5)) else {
            return self.fallback(format_args!("{x:.12e}"));
        };
        let (mut d, mut exp) = (s.digits, s.exp);
        if s.n <= 13 {
            d *= 10u64.pow(13 - s.n);
        } else {
            let cut = 10u64.pow(s.n - 13);
            let round_up = d % cut >= cut / 2;
            d /= cut;
            if round_up {
                d += 1;
                if d == 10u64.pow(13) {
                    // 9.99...9 rounds up to 10.00...0
                    d /= 10;
                    exp += 1;
                }
            }
        }
        if s.digits == 0 {
            exp = 0;
        }
        self.sign(&s);
        self.exponential(d, 13, exp);
        self
    }

    fn fallback(&mut self, args: std::fmt::Arguments) -> &mut Self {
        let _ = self.bytes.write_fmt(args);
        self
    }
}

/// The text `write` appends to an empty [`Text`], as a `String` (for the few numbers written
/// outside the long lists).
pub fn text_of(write: impl FnOnce(&mut Text)) -> String {
    let mut t = Text::default();
    write(&mut t);
    String::from_utf8(t.bytes).expect("the writers' text is ASCII")
}

/// Items encoded per block of [`write_binary`].
const BINARY_BLOCK: usize = 1 << 14;

/// Writes the bytes of items `0..n` in order, `encode(range, bytes)` appending those of a range
/// of items: a binary array streamed through one small buffer.
pub fn write_binary(
    w: &mut dyn Write,
    n: usize,
    encode: impl Fn(std::ops::Range<usize>, &mut Vec<u8>),
) -> io::Result<()> {
    let mut buffer = Vec::with_capacity(BINARY_BLOCK * 24);
    for start in (0..n).step_by(BINARY_BLOCK) {
        buffer.clear();
        encode(start..(start + BINARY_BLOCK).min(n), &mut buffer);
        w.write_all(&buffer)?;
    }
    Ok(())
}

/// Items per block of [`write_items`]: big enough that a block is worth a thread and that a
/// block of long lines passes the writer's 1 MiB buffer without a copy, small enough that a round
/// of blocks stays a few megabytes.
const BLOCK: usize = 1 << 14;

/// Writes the text of items `0..n` in order: `item(text, i)` appends item `i`. Blocks of items
/// are formatted in parallel while the previous round is being written, so the file streams
/// with two rounds of blocks in memory (their buffers reused from round to round) and its bytes
/// do not depend on the thread count.
pub fn write_items<F>(w: &mut dyn Write, n: usize, item: F) -> io::Result<()>
where
    F: Fn(&mut Text, usize) + Sync,
{
    let per_round = BLOCK * 2 * rayon::current_num_threads().max(1);
    let format_round = |start: usize, mut blocks: Vec<Text>| -> Vec<Text> {
        let end = (start + per_round).min(n);
        let starts: Vec<usize> = (start..end).step_by(BLOCK).collect();
        blocks.resize_with(starts.len(), Text::default);
        blocks.par_iter_mut().zip(starts).for_each(|(t, b)| {
            t.clear();
            for i in b..(b + BLOCK).min(end) {
                item(t, i);
            }
        });
        blocks
    };
    if n == 0 {
        return Ok(());
    }
    let mut ready = format_round(0, Vec::new());
    let mut spare = Vec::new();
    let mut start = per_round;
    loop {
        let mut next = Vec::new();
        let result = rayon::in_place_scope(|scope| {
            if start < n {
                let spare = std::mem::take(&mut spare);
                let next = &mut next;
                scope.spawn(move |_| *next = format_round(start, spare));
            }
            ready.iter().try_for_each(|t| w.write_all(&t.bytes))
        });
        result?;
        if start >= n {
            return Ok(());
        }
        spare = std::mem::replace(&mut ready, next);
        start += per_round;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(x: f64) {
        let mut t = Text::default();
        t.display(x).str(" ").debug(x).str(" ").exp(x).str(" ").exp12(x);
        let expected = format!("{x} {x:?} {x:e} {x:.12e}");
        assert_eq!(String::from_utf8(t.bytes).unwrap(), expected, "bits {:#x}", x.to_bits());
    }

    /// A small deterministic generator (xorshift), so the test needs no crate and repeats.
    struct Bits(u64);
    impl Bits {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }
    }

    #[test]
    fn every_format_matches_std_on_special_and_random_numbers() {
        let special = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.1,
            1e-4,
            9.999999999999999e-5,
            1e16,
            9999999999999998.0,
            1e15,
            123456789.0,
            5e-324,
            f64::MAX,
            f64::MIN_POSITIVE,
            9.9999999999995,
            9.99999999999995,
            0.99999999999995,
            1.00000000000005,
            2.5,
            1.0000000000005,
            6.123233995736766e-17,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for x in special {
            check(x);
        }
        let mut g = Bits(0x9e3779b97f4a7c15);
        for _ in 0..300_000 {
            check(f64::from_bits(g.next()));
        }
        // Magnitudes of coordinates, directions and constants, with every digit count.
        // Values with a short exact expansion, where ties between candidates occur.
        for x in [1.0 + 2f64.powi(-17), 1052730259603333.0 + 0.25, 1658206780088562.0 + 0.25, 2f64.powi(60) + 2048.0] {
            check(x);
            check(-x);
        }
        for _ in 0..300_000 {
            let bits = 1 + g.next() % 52;
            let m = (g.next() >> (64 - bits)) | 1;
            check(m as f64 * 2f64.powi(-((g.next() % 80) as i32)));
        }
        for _ in 0..300_000 {
            let m = (g.next() >> 11) as f64 / (1u64 << 53) as f64;
            let e = (g.next() % 40) as i32 - 20;
            let x = (m - 0.5) * 10f64.powi(e);
            check(x);
            let digits = 1 + g.next() % 17;
            let rounded: f64 = format!("{x:.*e}", digits as usize).parse().unwrap();
            check(rounded);
        }
    }

    #[test]
    fn integers_and_lists() {
        let mut t = Text::default();
        t.uint(0).str(",").uint(u64::MAX).str(";").uints([1, 22, 333], ", ");
        assert_eq!(String::from_utf8(t.bytes).unwrap(), format!("0,{};1, 22, 333", u64::MAX));
    }

    #[test]
    fn items_are_written_in_order_whatever_the_block_count() {
        for n in [0, 1, BLOCK - 1, BLOCK, 5 * BLOCK + 3, 40 * BLOCK + 1] {
            let mut out = Vec::new();
            write_items(&mut out, n, |t, i| {
                t.uint(i as u64).byte(b'\n');
            })
            .unwrap();
            let expected: String = (0..n).map(|i| format!("{i}\n")).collect();
            assert!(out == expected.as_bytes(), "n = {n}");
        }
    }
}
