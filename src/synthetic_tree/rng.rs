//! The random numbers of a tree: SplitMix64 (Steele, Lea & Flood 2014, the seeding generator of
//! Java's SplittableRandom and of the xoshiro family). Written out here rather than taken from
//! a crate because a tree must stay the same tree for a given seed for good: the generator and
//! the way each draw turns bits into a number are part of the population's definition.

use nalgebra::{UnitQuaternion, Vector3};

/// A deterministic stream of random numbers, one per (seed, attempt).
#[derive(Debug, Clone)]
pub struct SeededRng {
    state: u64,
}

const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl SeededRng {
    /// The stream of `seed`'s `attempt`-th draw (attempt 0 first; a tree that fails its checks
    /// is drawn again from the next attempt's stream).
    pub fn new(seed: u64, attempt: u32) -> Self {
        SeededRng { state: mix(seed ^ mix(u64::from(attempt).wrapping_add(GOLDEN_GAMMA))) }
    }

    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(GOLDEN_GAMMA);
        mix(self.state)
    }

    /// Uniform in [0, 1) (53 random bits).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Log-uniform in [lo, hi) (lo > 0).
    pub fn log_range(&mut self, lo: f64, hi: f64) -> f64 {
        (lo.ln() + (hi.ln() - lo.ln()) * self.uniform()).exp()
    }

    /// True with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        self.uniform() < p
    }

    /// Uniform in 0..n (n > 0).
    pub fn index(&mut self, n: usize) -> usize {
        ((self.uniform() * n as f64) as usize).min(n.saturating_sub(1))
    }

    /// An index drawn with the given (non-negative, not all zero) weights.
    pub fn weighted(&mut self, weights: &[f64]) -> usize {
        let total: f64 = weights.iter().sum();
        let mut x = self.uniform() * total;
        for (i, w) in weights.iter().enumerate() {
            if x < *w {
                return i;
            }
            x -= w;
        }
        weights.iter().rposition(|w| *w > 0.0).unwrap_or(0)
    }

    /// A rotation uniform over SO(3) (a unit quaternion from four normal deviates).
    pub fn rotation(&mut self) -> UnitQuaternion<f64> {
        loop {
            let q = nalgebra::Quaternion::new(self.normal(), self.normal(), self.normal(), self.normal());
            if q.norm() > 1e-6 {
                return UnitQuaternion::from_quaternion(q);
            }
        }
    }

    /// A standard normal deviate (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        let u = 1.0 - self.uniform();
        let v = self.uniform();
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }

    /// A unit vector perpendicular to the unit `t`, uniform in angle about it, given the frame
    /// normal `n` (perpendicular to `t`): `cos φ n + sin φ (t × n)`.
    pub fn perpendicular(&mut self, t: &Vector3<f64>, n: &Vector3<f64>) -> Vector3<f64> {
        let phi = self.range(0.0, std::f64::consts::TAU);
        n * phi.cos() + t.cross(n) * phi.sin()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_reproducible_distinct_and_uniform() {
        let draws = |seed, attempt| {
            let mut r = SeededRng::new(seed, attempt);
            (0..5).map(|_| r.next_u64()).collect::<Vec<_>>()
        };
        assert_eq!(draws(7, 0), draws(7, 0));
        assert_ne!(draws(7, 0), draws(7, 1));
        assert_ne!(draws(7, 0), draws(8, 0));
        // The first value of SplitMix64 seeded with 0 (the reference implementation's).
        let mut r = SeededRng { state: 0 };
        assert_eq!(r.next_u64(), 0xE220_A839_7B1D_CDAF);
        let mut r = SeededRng::new(1, 0);
        let n = 100_000;
        let mut bins = [0usize; 10];
        for _ in 0..n {
            let u = r.uniform();
            assert!((0.0..1.0).contains(&u));
            bins[(u * 10.0) as usize] += 1;
        }
        assert!(bins.iter().all(|&b| (b as f64 - n as f64 / 10.0).abs() < 500.0), "{bins:?}");
        assert_eq!((0..1000).map(|_| r.weighted(&[0.0, 1.0, 0.0])).filter(|&i| i != 1).count(), 0);
    }
}
