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
//! # Digits found in integers
//! Where the writers' numbers lie (|x| from about 1e-15 to 1e17), the digits come from exact
//! integer arithmetic instead of zmij's text, which had to be read back: x = m x 2^e times
//! 10^q is m x 5^q x 2^(e + q), with 5^q in a table of 128-bit integers, so an integer part and a
//! remainder by a shift. The shortest digits ([`Shortest::exact`]): the integers between the ends
//! of x's round-trip interval at 17 or 18 digits, the largest power of ten with a multiple
//! among them, the multiple closest to x. `{:.12e}` ([`thirteen_digits`]): x scaled to 13 digits
//! before the point, rounded by its remainder. A tie (a remainder of exactly one half) is left
//! to the paths below. The unit tests compare both with std and with zmij on random numbers.
//!
//! Elsewhere `{:.12e}` (13 significant digits, correctly rounded) is derived from the shortest
//! digits D: with at most 13 digits, D padded with zeros is the answer (the binary value lies
//! within half an ulp of D, far from a 13-digit rounding boundary); with 15 or more, rounding D
//! to 13 digits rounds the binary value alike (a 14-digit midpoint between the two would itself
//! be a shorter candidate in the round-trip interval); with exactly 14 digits ending in 5, D may
//! be that midpoint and the binary value decides, so std's own formatting is asked (as for
//! subnormals, whose precision is below 13 digits).

use rayon::prelude::*;
use std::cmp::Ordering;
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
        if let Some(exact) = Shortest::exact(x) {
            return Some(exact);
        }
        let out = Shortest::parse(zmij::Buffer::new().format_finite(x).as_bytes());
        (!out.halfway_from_a_neighbour(x.abs())).then_some(out)
    }

    /// The shortest digits of `x` found exactly in integers, without zmij's text to read back
    /// (that reading and the layout after it cost three times zmij's own work in `exp`, the
    /// OpenFOAM points): x x 10^q and the ends of its round-trip interval (halfway to the
    /// neighbouring doubles, included when the significand is even, as std reads them) scaled to
    /// 17 or 18 digits before the point, the largest power of ten t with a multiple in the
    /// interval, the multiple closest to x. `None` where std or zmij decides: zero, subnormals,
    /// |x| outside about [1e-15, 1e17) (the products exceed 128 bits), and a tie between the two
    /// multiples around x.
    fn exact(x: f64) -> Option<Shortest> {
        let bits = x.abs().to_bits();
        let biased = (bits >> 52) as i32;
        if biased == 0 || biased == 0x7ff {
            return None;
        }
        let fraction = bits & ((1u64 << 52) - 1);
        let m = fraction | (1u64 << 52);
        let q = 16 - (((biased - 1023) * 78913) >> 18); // x x 10^q in [10^16, 2 x 10^17)
        let five = *FIVES.get(usize::try_from(q).ok()?)?;
        let shift = u32::try_from(1077 - biased - q).ok().filter(|s| (1..128).contains(s))?;
        // 4 x x, its neighbours at +-2 (+1 below a power of two), times 5^q: x x 10^q x 2^shift.
        let value = (4 * m) as u128 * five;
        let upper = value + 2 * five;
        let lower = value - if fraction == 0 && biased > 1 { five } else { 2 * five };
        let (inclusive, mask) = (m.is_multiple_of(2), (1u128 << shift) - 1);
        let hi = (upper >> shift) as u64 - (!inclusive && upper & mask == 0) as u64;
        let lo = (lower >> shift) as u64 + (!inclusive || lower & mask != 0) as u64;
        let (mut t, mut zeros) = (1u64, 0);
        while hi / (10 * t) * (10 * t) >= lo {
            t *= 10;
            zeros += 1;
        }
        let (whole, rest) = ((value >> shift) as u64, value & mask);
        let down = whole / t * t;
        // Where x lies between `down` and `down + t`, against their midpoint.
        let against_half = match t {
            1 => rest.cmp(&(1u128 << (shift - 1))),
            _ => (whole - down).cmp(&(t / 2)).then(if rest == 0 { Ordering::Equal } else { Ordering::Greater }),
        };
        let mut digits = match (down >= lo, down + t <= hi, against_half) {
            (true, true, Ordering::Equal) | (false, false, _) => return None,
            (true, false, _) | (true, true, Ordering::Less) => down / t,
            _ => down / t + 1,
        };
        while digits % 10 == 0 {
            digits /= 10;
            zeros += 1;
        }
        let n = decimal_len(digits);
        Some(Shortest { negative: x.is_sign_negative(), digits, n, exp: n as i32 - 1 + zeros - q })
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

/// 5^0 to 5^31: times a 53-bit significand, they fit in 128 bits.
const FIVES: [u128; 32] = {
    let mut t = [1u128; 32];
    let mut i = 1;
    while i < 32 {
        t[i] = 5 * t[i - 1];
        i += 1;
    }
    t
};

/// The 13 significant digits of `{:.12e}` of `a` (> 0, normal) and their exponent, found
/// exactly in integers: a x 10^q = m x 5^q x 2^(e + q) for a = m x 2^e, its integer part and
/// remainder by a shift. Through zmij's shortest digits (the text, read back, rounded), `exp12`
/// cost three times `display`, and the three CalculiX and Abaqus decks write some seven million
/// such numbers at 0.8 M hexes. `None` where std decides: q outside 0..=31 (`a` outside about
/// [1e-19, 1e13)), zero, subnormals, non-finite values, and a remainder of exactly one half,
/// where the rounding of a tie is std's to choose.
fn thirteen_digits(a: f64) -> Option<(u64, i32)> {
    const TEN13: u64 = 10_000_000_000_000;
    let bits = a.to_bits();
    let biased = ((bits >> 52) & 0x7ff) as i32;
    if biased == 0 || biased == 0x7ff || a < 0.0 {
        return None;
    }
    let m = (bits & ((1u64 << 52) - 1)) | (1u64 << 52);
    let e = biased - 1075;
    // floor(log2 a) x log10 2, rounded down: 10^k <= a < 2 x 10^(k + 1), so a x 10^(12 - k) lies
    // in [10^12, 2 x 10^13) and has 13 or 14 digits before the point.
    let k = ((biased - 1023) * 78913) >> 18;
    let scaled = |q: i32| -> Option<(u64, u128, u32)> {
        let shift = u32::try_from(-(e + q)).ok().filter(|s| (1..128).contains(s))?;
        let p = m as u128 * FIVES.get(usize::try_from(q).ok()?)?;
        Some(((p >> shift) as u64, p & ((1u128 << shift) - 1), shift))
    };
    let mut q = 12 - k;
    let mut s = scaled(q)?;
    if s.0 >= TEN13 {
        q -= 1;
        s = scaled(q)?;
    }
    let (int, rest, shift) = s;
    let d = match rest.cmp(&(1u128 << (shift - 1))) {
        Ordering::Less => int,
        Ordering::Greater => int + 1,
        Ordering::Equal => return None,
    };
    debug_assert!((TEN13 / 10..=TEN13).contains(&d));
    // 9.9999999999999x rounds up to 10.00...0
    Some(if d == TEN13 { (d / 10, 13 - q) } else { (d, 12 - q) })
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

/// The number of decimal digits of `x` (1 for 0): from the bit length, times log10 2 (1233 /
/// 4096, exact up to 2^64), one less when `x` is below the power of ten that gives.
fn decimal_len(x: u64) -> u32 {
    const POWERS: [u64; 20] = {
        let mut p = [1u64; 20];
        let mut i = 1;
        while i < 20 {
            p[i] = 10 * p[i - 1];
            i += 1;
        }
        p
    };
    let y = x | 1; // 0 has the digits of 1; no power of ten above 1 is odd, so the count stays
    let guess = ((64 - y.leading_zeros()) * 1233) >> 12; // 0..=19
    guess + 1 - (y < POWERS[guess as usize]) as u32
}

/// The eight digits of `x` (< 10^8, leading zeros included) as ASCII in a `u64`, the first in
/// the lowest byte: the two halves of four digits in lanes of 32 bits, each split into two pairs
/// in lanes of 16, each pair into two digits in bytes, every lane at once by a multiplication
/// (v x 10486 / 2^20 is v / 100 below 10^4, v x 103 / 2^10 is v / 10 below 100).
fn eight_digits(x: u32) -> u64 {
    let fours = (x / 10_000) as u64 | ((x % 10_000) as u64) << 32;
    let hundreds = ((fours * 10486) >> 20) & 0x0000_007f_0000_007f;
    let pairs = hundreds | (fours - hundreds * 100) << 16;
    let tens = ((pairs * 103) >> 10) & 0x000f_000f_000f_000f;
    (tens | (pairs - tens * 10) << 8) | 0x3030_3030_3030_3030
}

/// Stores the n digits of `v` (v < 10^n, 1 <= n <= 20; leading zeros where it has fewer) at
/// `out`, eight per store ([`eight_digits`]), a shorter first group shifted to the end of its
/// eight bytes and overwritten by the next: at most 24 bytes from `out` are written.
///
/// # Safety
/// `out` must be valid for writes of 24 bytes.
unsafe fn store_digits(out: *mut u8, v: u64, n: usize) {
    const E8: u64 = 100_000_000;
    // SAFETY (of every store): at `out` or n - 8, n - 16 bytes after it, within its 24 bytes.
    let store = |at: *mut u8, ascii: u64| unsafe { at.cast::<u64>().write_unaligned(ascii.to_le()) };
    unsafe {
        if n <= 8 {
            store(out, eight_digits(v as u32) >> (8 * (8 - n)));
        } else if n <= 16 {
            store(out, eight_digits((v / E8) as u32) >> (8 * (16 - n)));
            store(out.add(n - 8), eight_digits((v % E8) as u32));
        } else {
            store(out, eight_digits((v / (E8 * E8)) as u32) >> (8 * (24 - n)));
            store(out.add(n - 16), eight_digits((v / E8 % E8) as u32));
            store(out.add(n - 8), eight_digits((v % E8) as u32));
        }
    }
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
        self.put_digits(b"", x, decimal_len(x));
        self
    }
    /// Integers separated by `sep` (at most four bytes).
    pub fn uints(&mut self, xs: impl IntoIterator<Item = u64>, sep: &str) -> &mut Self {
        for (i, x) in xs.into_iter().enumerate() {
            self.put_digits(if i > 0 { sep.as_bytes() } else { b"" }, x, decimal_len(x));
        }
        self
    }

    /// The n digits of `digits` (< 10^n, 1 <= n <= 20; leading zeros written when it has fewer).
    fn digits(&mut self, digits: u64, n: u32) {
        self.put_digits(b"", digits, n);
    }
    /// `sep` (at most four bytes) then the n digits of `v` (v < 10^n, 1 <= n <= 20; leading zeros
    /// where it has fewer), written in place after one reservation ([`store_digits`]). Digits
    /// written one pair at a time, then copied, cost a call to memmove per number (a tenth of the
    /// writers' time), and a separator appended on its own another.
    fn put_digits(&mut self, sep: &[u8], v: u64, n: u32) {
        assert!(sep.len() <= 4 && (1..=20).contains(&n));
        debug_assert!(v.checked_ilog10().is_none_or(|l| l < n));
        let start = self.bytes.len();
        self.bytes.reserve(32);
        // The separator's bytes gathered in a word and stored at once (a loop of byte copies is
        // compiled into a call to memcpy).
        let word = sep.iter().rev().fold(0u32, |w, &b| w << 8 | b as u32);
        // SAFETY: 4 + 24 bytes from `start` are reserved; the first sep.len() + n are written and
        // become the text.
        unsafe {
            let out = self.bytes.as_mut_ptr().add(start);
            out.cast::<u32>().write_unaligned(word.to_le());
            store_digits(out.add(sep.len()), v, n as usize);
            self.bytes.set_len(start + sep.len() + n as usize);
        }
    }
    fn sign(&mut self, s: &Shortest) {
        if s.negative {
            self.bytes.push(b'-');
        }
    }
    /// d1.d2...dn e k of n digits (1 <= n <= 20), without the sign, in place after one
    /// reservation: the digits stored one place to the right ([`store_digits`]), the first moved
    /// back over a point (splitting them at the first digit took a division by a power of ten
    /// known only at run time), then `e`, the sign and the exponent's digits gathered in a word.
    fn exponential(&mut self, digits: u64, n: u32, exp: i32) {
        assert!((1..=20).contains(&n));
        let (n, start) = (n as usize, self.bytes.len());
        let (negative, e) = ((exp < 0) as u64, exp.unsigned_abs()); // |exp| < 1000
        let e_len = decimal_len(e as u64) as u64;
        let e_digits = eight_digits(e % 100_000_000) >> (8 * (8 - e_len));
        let tail = b'e' as u64 | (negative * ((b'-' as u64) << 8)) | e_digits << (8 * (1 + negative));
        self.bytes.reserve(32);
        // SAFETY: 32 bytes from `start` are reserved: the digits take 1 + 24 at most, the tail 8
        // from at most 21; the first len + 1 + negative + e_len are written and become the text.
        unsafe {
            let out = self.bytes.as_mut_ptr().add(start);
            store_digits(out.add(1), digits, n);
            out.write(out.add(1).read());
            let len = if n > 1 { n + 1 } else { 1 };
            out.add(1).write(b'.'); // overwritten by the tail when n is 1
            out.add(len).cast::<u64>().write_unaligned(tail.to_le());
            self.bytes.set_len(start + len + (1 + negative + e_len) as usize);
        }
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
        if let Some((d, exp)) = thirteen_digits(x.abs()) {
            if x.is_sign_negative() {
                self.bytes.push(b'-');
            }
            self.exponential(d, 13, exp);
            return self;
        }
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
            let items = b..(b + BLOCK).min(end);
            item(t, items.start);
            // Room for the block at once, from its first item and a margin (items grow longer
            // along a list, as their labels do): grown by doubling, a block was copied as it grew.
            t.bytes.reserve(t.len() * items.len() * 9 / 8 + 64);
            items.skip(1).for_each(|i| item(t, i));
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
        // Ties at the 13th digit (std rounds them; `thirteen_digits` leaves them to it) and
        // their neighbours: n + 1/2 of 13 digits, n + 1/4 of 12 digits.
        for _ in 0..10_000 {
            let n = (1_000_000_000_000 + g.next() % 9_000_000_000_000) as f64;
            for x in [n + 0.5, (n / 10.0).floor() + 0.25, n + 1.5, n - 0.5] {
                check(x);
                check(f64::from_bits(x.to_bits() + 1));
                check(f64::from_bits(x.to_bits() - 1));
            }
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

    /// The exact path against zmij's digits, on the magnitudes the writers meet most (lengths
    /// in mm and m, unit components) and at powers of two, where the interval is lopsided.
    #[test]
    fn exact_digits_are_zmijs() {
        let mut g = Bits(0x2545f4914f6cdd1d);
        let (mut exact, mut total) = (0, 0);
        for i in 0..2_000_000 {
            let x = match i % 4 {
                0 => f64::from_bits(g.next()),
                1 => ((g.next() >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 10f64.powi((g.next() % 36) as i32 - 18),
                2 => 2f64.powi((g.next() % 120) as i32 - 60) * if g.next().is_multiple_of(2) { 1.0 } else { -1.0 },
                _ => f64::from_bits(g.next() % (1 << 20) + ((g.next() % 200 + 924) << 52)),
            };
            if !x.is_finite() {
                continue;
            }
            total += 1;
            let Some(s) = Shortest::exact(x) else { continue };
            exact += 1;
            let z = Shortest::parse(zmij::Buffer::new().format_finite(x).as_bytes());
            let same = (s.negative, s.digits, s.n, s.exp) == (z.negative, z.digits, z.n, z.exp);
            assert!(
                same,
                "bits {:#x}: {} {} {} against zmij's {} {} {}",
                x.to_bits(),
                s.digits,
                s.n,
                s.exp,
                z.digits,
                z.n,
                z.exp
            );
        }
        // Every value of the magnitudes written (kinds 1 to 3) and some of the random bits.
        assert!(exact > total / 2, "the exact path took {exact} of {total}");
    }

    #[test]
    fn integers_and_lists() {
        let mut t = Text::default();
        t.uint(0).str(",").uint(u64::MAX).str(";").uints([1, 22, 333], ", ");
        assert_eq!(String::from_utf8(t.bytes).unwrap(), format!("0,{};1, 22, 333", u64::MAX));
        // Every digit count, at and around the powers of ten, and random values.
        let mut g = Bits(0x853c49e6748fea9b);
        let mut xs: Vec<u64> = (0..20).flat_map(|k| [10u64.pow(k) - 1, 10u64.pow(k), 10u64.pow(k) + 1]).collect();
        xs.extend((0..100_000).map(|i| g.next() >> (i % 64)));
        let mut t = Text::default();
        t.uints(xs.iter().copied(), " ");
        let expected: Vec<String> = xs.iter().map(|x| x.to_string()).collect();
        assert_eq!(String::from_utf8(t.bytes).unwrap(), expected.join(" "));
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
