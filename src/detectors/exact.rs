//! Order-free sums of f64 values: a run's totals come out as the same bits however its batches
//! are grouped or ordered (threads, MPI ranks, merged partial runs), because each total is kept
//! as an integer sum of fixed-point parts and rounded only when read.
//!
//! The binary line is cut into 28-bit slots: slot s holds the weights 2^(28s − 1074) up to
//! 2^(28s − 1047), so slot 0 starts at the smallest subnormal and slot 74 holds f64::MAX's top bit.
//! An f64's 53 significant bits span at most three slots. An `ExactSum` keeps three i64 words:
//! the sums of every added value's parts in the highest slot any added value reached (T) and in
//! the two below it. Parts below slot T − 2 are dropped, and words never carry into each other,
//! so the words are Σ over all values of their parts in slots T − 2..=T whatever the order or
//! grouping: the sum is a function of the set of values alone. What is dropped is below
//! 2^−56 of the largest value, per value: no more than f64 addition in any order loses.
//!
//! Each part is below 2^28 in magnitude, so a word holds 2^35 additions without overflow; every
//! accumulator in photon takes at most one value per batch (`MAX_VALUES`).

const SLOT_BITS: i32 = 28;
const SLOT_MASK: u64 = (1 << SLOT_BITS) - 1;
/// Weight of slot 0's lowest bit: the smallest subnormal, 2^−1074.
const LOWEST_EXPONENT: i32 = -1074;
/// `top` of a sum that has seen no value.
const EMPTY: i32 = -1;
/// `top` of a sum that has seen a NaN or an infinity: it reads as NaN, so the output's finiteness
/// checks report it instead of a wrong number.
const POISONED: i32 = i32::MAX;
/// Highest slot an f64 reaches: (1023 + 1074) / 28.
pub const MAX_SLOT: i32 = 74;
/// Values one sum can take without a word overflowing: 2^35 parts below 2^28 stay below 2^63.
pub const MAX_VALUES: u64 = 1 << 35;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ExactSum {
    /// Slot of `words[0]`; `words[k]` is slot `top − k`.
    top: i32,
    words: [i64; 3],
}

/// The 28-bit parts (bits 0–27, 28–55, 56–83) of m·2^shift for m < 2^53, shift < 28, in u64
/// arithmetic (a u128 shift cost twice the instructions): the wrapping shift keeps bits 0–63,
/// enough for the two low parts, and bits 56 and up are m >> (56 − shift).
#[inline(always)]
fn split_parts(m: u64, shift: u32) -> (u64, u64, u64) {
    let low_bits = m.wrapping_shl(shift);
    (low_bits & SLOT_MASK, (low_bits >> SLOT_BITS) & SLOT_MASK, m >> (2 * SLOT_BITS as u32 - shift))
}

impl Default for ExactSum {
    fn default() -> Self {
        ExactSum { top: EMPTY, words: [0; 3] }
    }
}

impl ExactSum {
    /// Adds `x` (the film's merge adds millions a second: kept branch-light).
    #[inline(always)]
    pub fn add(&mut self, x: f64) {
        let bits = x.to_bits();
        let biased = ((bits >> 52) & 0x7ff) as i32;
        if biased == 0x7ff {
            // Words left behind would make equal sums differ by the order they were poisoned in.
            *self = ExactSum { top: POISONED, words: [0; 3] };
            return;
        }
        let fraction = bits & ((1 << 52) - 1);
        // x = m · 2^(p − 1074) with p the position of m's lowest bit on the slot line.
        let (m, p) = if biased == 0 { (fraction, 0) } else { (fraction | 1 << 52, biased - 1) };
        if m == 0 || self.top == POISONED {
            return;
        }
        let slot = p / SLOT_BITS;
        let (lo, mid, hi) = split_parts(m, (p % SLOT_BITS) as u32);
        // Two's-complement negation by mask: (v ^ s) − s is v for s = 0 and −v for s = −1.
        let s = -((bits >> 63) as i64);
        let signed = |v: u64| ((v as i64) ^ s) - s;
        let (lo, mid, hi) = (signed(lo), signed(mid), signed(hi));
        let value_top = slot + (hi != 0) as i32 + (hi != 0 || mid != 0) as i32;
        self.raise_top(value_top);
        // Where the value's three slots (slot + 2, + 1, + 0) fall in the window: a part above
        // it is zero, one below it is dropped.
        let w = &mut self.words;
        match self.top - (slot + 2) {
            -2 => w[0] += lo,
            -1 => {
                w[0] += mid;
                w[1] += lo;
            }
            0 => {
                w[0] += hi;
                w[1] += mid;
                w[2] += lo;
            }
            1 => {
                w[1] += hi;
                w[2] += mid;
            }
            2 => w[2] += hi,
            _ => {}
        }
    }

    /// Adds another sum: the result is the sum of both sets of values. Sums of at most
    /// `MAX_VALUES` values in all never overflow; `Overflow` (and `self` left unchanged) means
    /// more, which only a state file that no run wrote can hold.
    pub fn add_sum(&mut self, other: &ExactSum) -> Result<(), Overflow> {
        if other.top == EMPTY || self.top == POISONED {
            return Ok(());
        }
        if other.top == POISONED {
            *self = ExactSum { top: POISONED, words: [0; 3] };
            return Ok(());
        }
        let mut sum = *self;
        sum.raise_top(other.top);
        let shift = (sum.top - other.top) as usize;
        for k in 0..3usize.saturating_sub(shift) {
            sum.words[k + shift] = sum.words[k + shift].checked_add(other.words[k]).ok_or(Overflow)?;
        }
        *self = sum;
        Ok(())
    }

    /// Moves the window up to slot `t`, dropping the words that fall below it.
    #[inline]
    fn raise_top(&mut self, t: i32) {
        if t <= self.top {
            return;
        }
        let [w0, w1, _] = self.words;
        self.words = match t - self.top {
            1 => [0, w0, w1],
            2 => [0, 0, w0],
            _ => [0; 3],
        };
        self.top = t;
    }

    /// The sum, rounded once to the nearest f64 (ties to even).
    pub fn value(&self) -> f64 {
        match self.top {
            EMPTY => 0.0,
            POISONED => f64::NAN,
            top => {
                // |words| < 2^63, so the window's integer is below 2^120.
                let n = ((self.words[0] as i128) << (2 * SLOT_BITS))
                    + ((self.words[1] as i128) << SLOT_BITS)
                    + self.words[2] as i128;
                // `as f64` rounds to nearest-even; scaling by a power of two is then exact
                // outside the subnormal range.
                scale_by_power_of_two(n as f64, SLOT_BITS * (top - 2) + LOWEST_EXPONENT)
            }
        }
    }

    /// The state as 28 little-endian bytes: top (i32), then the three words (i64).
    pub fn to_bytes(&self) -> [u8; 28] {
        let mut b = [0u8; 28];
        b[..4].copy_from_slice(&self.top.to_le_bytes());
        for (k, w) in self.words.iter().enumerate() {
            b[4 + 8 * k..12 + 8 * k].copy_from_slice(&w.to_le_bytes());
        }
        b
    }

    /// The inverse of `to_bytes`; None if `top` is no slot (a corrupt file).
    pub fn from_bytes(b: &[u8; 28]) -> Option<ExactSum> {
        let top = i32::from_le_bytes(b[..4].try_into().ok()?);
        if !(top == EMPTY || top == POISONED || (0..=MAX_SLOT).contains(&top)) {
            return None;
        }
        let mut words = [0i64; 3];
        for (k, w) in words.iter_mut().enumerate() {
            *w = i64::from_le_bytes(b[4 + 8 * k..12 + 8 * k].try_into().ok()?);
        }
        if top == EMPTY && words != [0; 3] {
            return None;
        }
        Some(ExactSum { top, words })
    }
}

/// Four exact sums side by side (a pixel's X, Y, Z and Y's square term), stored lane by lane
/// (each field holds lane k at index k) so that AVX2 adds a value to each at once (`add_avx2`);
/// lane k is the `ExactSum` `lane(k)`, with the same bits whichever way it was added to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(C, align(64))]
pub struct ExactSum4 {
    top: [i64; 4],
    /// words[j][k]: lane k's word j (slot top − j).
    words: [[i64; 4]; 3],
}

impl Default for ExactSum4 {
    fn default() -> Self {
        ExactSum4 { top: [EMPTY as i64; 4], words: [[0; 4]; 3] }
    }
}

impl ExactSum4 {
    pub fn from_lanes(lanes: [ExactSum; 4]) -> Self {
        let mut s = ExactSum4::default();
        for (k, lane) in lanes.iter().enumerate() {
            s.set_lane(k, *lane);
        }
        s
    }

    #[inline]
    pub fn lane(&self, k: usize) -> ExactSum {
        ExactSum { top: self.top[k] as i32, words: [self.words[0][k], self.words[1][k], self.words[2][k]] }
    }

    pub fn lanes(&self) -> [ExactSum; 4] {
        [self.lane(0), self.lane(1), self.lane(2), self.lane(3)]
    }

    #[inline]
    fn set_lane(&mut self, k: usize, s: ExactSum) {
        self.top[k] = s.top as i64;
        for j in 0..3 {
            self.words[j][k] = s.words[j];
        }
    }

    /// Adds another's lanes to these, lane by lane (`ExactSum::add_sum`).
    pub fn add_sums(&mut self, o: &ExactSum4) -> Result<(), Overflow> {
        for k in 0..4 {
            let mut s = self.lane(k);
            s.add_sum(&o.lane(k))?;
            self.set_lane(k, s);
        }
        Ok(())
    }

    /// Each lane's sum, rounded once.
    pub fn values(&self) -> [f64; 4] {
        self.lanes().map(|s| s.value())
    }

    /// Adds v[k] to lane k, one lane at a time.
    #[inline]
    pub fn add(&mut self, v: [f64; 4]) {
        for (k, x) in v.into_iter().enumerate() {
            let mut s = self.lane(k);
            s.add(x);
            self.set_lane(k, s);
        }
    }

    /// `add` in AVX2, all four lanes at once, for lanes whose values are normal numbers or ±0
    /// and whose sums are not poisoned (any other lane sends all four to `add`). The window is
    /// raised as `raise_top` does; then each value's parts in the window's slots T − 2, T − 1, T
    /// are m's bits from r, r − 28 and r − 56 up, r = p − 28(T − 2) being the position of m's
    /// lowest bit above the window's: the same parts `ExactSum::add` places slot by slot (a
    /// variable shift by a count outside 0..=63 gives 0, which drops what lies below).
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    pub unsafe fn add_avx2(&mut self, v: [f64; 4]) {
        use std::arch::x86_64::*;
        let one = |x: i64| _mm256_set1_epi64x(x);
        let zero = _mm256_setzero_si256();
        // SAFETY: `v` is four f64, and each field is a 32-byte row at a multiple of 32 bytes
        // from the 64-aligned start.
        let bits = unsafe { _mm256_loadu_si256(v.as_ptr() as *const __m256i) };
        let load = |row: &[i64; 4]| unsafe { _mm256_load_si256(row.as_ptr() as *const __m256i) };
        let top = load(&self.top);
        let biased = _mm256_and_si256(_mm256_srli_epi64::<52>(bits), one(0x7ff));
        let fraction = _mm256_and_si256(bits, one((1 << 52) - 1));
        let exponent_zero = _mm256_cmpeq_epi64(biased, zero);
        let subnormal = _mm256_andnot_si256(_mm256_cmpeq_epi64(fraction, zero), exponent_zero);
        let not_finite = _mm256_cmpeq_epi64(biased, one(0x7ff));
        let poisoned = _mm256_cmpeq_epi64(top, one(POISONED as i64));
        let rare = _mm256_or_si256(_mm256_or_si256(subnormal, not_finite), poisoned);
        if _mm256_movemask_pd(_mm256_castsi256_pd(rare)) != 0 {
            self.add(v);
            return;
        }
        // Every lane is ±0 (adds nothing, moves nothing) or normal: m = 1.fraction, x = m·2^(p − 1074).
        let m = _mm256_andnot_si256(exponent_zero, _mm256_or_si256(fraction, one(1 << 52)));
        let p = _mm256_sub_epi64(biased, one(1));
        // m's top bit is at p + 52: its slot ⌊(p + 52)/28⌋ = (p + 52)·2341 >> 16, exact for
        // p + 52 < 5461 (and p + 52 ≤ 2097).
        let value_top = _mm256_srli_epi64::<16>(_mm256_mul_epu32(_mm256_add_epi64(p, one(52)), one(2341)));
        let raise = _mm256_andnot_si256(exponent_zero, _mm256_cmpgt_epi64(value_top, top));
        let new_top = _mm256_blendv_epi8(top, value_top, raise);
        // The words move down by the rise: [w0, w1, w2] → [0, w0, w1], [0, 0, w0] or zeros.
        let rise = _mm256_sub_epi64(new_top, top);
        let (by0, by1, by2) =
            (_mm256_cmpeq_epi64(rise, zero), _mm256_cmpeq_epi64(rise, one(1)), _mm256_cmpeq_epi64(rise, one(2)));
        let [w0, w1, w2] = [load(&self.words[0]), load(&self.words[1]), load(&self.words[2])];
        let (w0, w1, w2) = (
            _mm256_and_si256(w0, by0),
            _mm256_or_si256(_mm256_and_si256(w1, by0), _mm256_and_si256(w0, by1)),
            _mm256_or_si256(
                _mm256_or_si256(_mm256_and_si256(w2, by0), _mm256_and_si256(w1, by1)),
                _mm256_and_si256(w0, by2),
            ),
        );
        // r = p − 28(T − 2) = p − 28T + 56 (28T = 32T − 4T).
        let r = _mm256_add_epi64(
            _mm256_sub_epi64(p, _mm256_sub_epi64(_mm256_slli_epi64::<5>(new_top), _mm256_slli_epi64::<2>(new_top))),
            one(56),
        );
        let bits_from = |at: i64| {
            let c = _mm256_sub_epi64(r, one(at));
            _mm256_or_si256(_mm256_sllv_epi64(m, c), _mm256_srlv_epi64(m, _mm256_sub_epi64(zero, c)))
        };
        let mask = one(SLOT_MASK as i64);
        let (lo, mid, hi) =
            (_mm256_and_si256(bits_from(0), mask), _mm256_and_si256(bits_from(28), mask), bits_from(56));
        // (v ^ s) − s negates where s = −1, the negative values.
        let s = _mm256_cmpgt_epi64(zero, bits);
        let signed = |v: __m256i| _mm256_sub_epi64(_mm256_xor_si256(v, s), s);
        let store = |row: &mut [i64; 4], v: __m256i| unsafe { _mm256_store_si256(row.as_mut_ptr() as *mut __m256i, v) };
        store(&mut self.top, new_top);
        store(&mut self.words[0], _mm256_add_epi64(w0, signed(hi)));
        store(&mut self.words[1], _mm256_add_epi64(w1, signed(mid)));
        store(&mut self.words[2], _mm256_add_epi64(w2, signed(lo)));
    }
}

/// x · 2^e, in steps that stay inside f64's exponent range.
fn scale_by_power_of_two(mut x: f64, mut e: i32) -> f64 {
    let pow2 = |k: i32| f64::from_bits(((k + 1023) as u64) << 52);
    while e > 1023 {
        x *= pow2(1023);
        e -= 1023;
    }
    while e < -1022 {
        x *= pow2(-1022);
        e += 1022;
        if x == 0.0 {
            return x;
        }
    }
    x * pow2(e)
}

/// A merge of sums whose words would overflow: more values than `MAX_VALUES` in all.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Overflow;

impl std::fmt::Display for Overflow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("its exact sums overflow when added to the others': no run of photon writes such a state")
    }
}

/// Element-wise `ExactSum`s behind a vector of f64 totals.
pub fn add_all(into: &mut [ExactSum], from: &[ExactSum]) -> Result<(), Overflow> {
    for (a, b) in into.iter_mut().zip(from) {
        a.add_sum(b)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Sampler;

    fn below(rng: &mut Sampler, n: usize) -> usize {
        (rng.uniform() * n as f64) as usize
    }

    /// The correctly rounded sum (Shewchuk's exact partials, as Python's math.fsum): the reference.
    fn fsum(values: &[f64]) -> f64 {
        let mut partials: Vec<f64> = Vec::new();
        for &v in values {
            let mut x = v;
            let mut kept = 0;
            for i in 0..partials.len() {
                let mut y = partials[i];
                if x.abs() < y.abs() {
                    std::mem::swap(&mut x, &mut y);
                }
                let hi = x + y;
                let lo = y - (hi - x);
                if lo != 0.0 {
                    partials[kept] = lo;
                    kept += 1;
                }
                x = hi;
            }
            partials.truncate(kept);
            partials.push(x);
        }
        // Sum from the top, then correct a half-way case as fsum does.
        let mut n = partials.len();
        if n == 0 {
            return 0.0;
        }
        n -= 1;
        let mut hi = partials[n];
        let mut lo = 0.0;
        while n > 0 {
            let x = hi;
            n -= 1;
            let y = partials[n];
            hi = x + y;
            let yr = hi - x;
            lo = y - yr;
            if lo != 0.0 {
                break;
            }
        }
        if n > 0 && ((lo < 0.0 && partials[n - 1] < 0.0) || (lo > 0.0 && partials[n - 1] > 0.0)) {
            let y = lo * 2.0;
            let x = hi + y;
            if y == x - hi {
                hi = x;
            }
        }
        hi
    }

    fn sum_of(values: &[f64]) -> ExactSum {
        let mut s = ExactSum::default();
        for &v in values {
            s.add(v);
        }
        s
    }

    /// Values of mixed sign over `decades` decades around 1.
    fn values(rng: &mut Sampler, n: usize, decades: f64) -> Vec<f64> {
        (0..n)
            .map(|_| {
                let v = 10f64.powf(decades * (rng.uniform() - 0.5)) * (0.5 + 0.5 * rng.uniform());
                if rng.uniform() < 0.3 {
                    -v
                } else {
                    v
                }
            })
            .collect()
    }

    /// AVX2's four lanes at once give each lane the bits the scalar sum gives it, value by
    /// value: across 600 decades (windows raised by one, two and more slots, values dropped
    /// below the window), with ±0, both signs, subnormals, f64::MAX, infinities and NaN mixed in
    /// (the last three are handed to the scalar path), from empty sums and from full ones.
    #[test]
    fn four_lanes_at_once_match_the_scalar_sum() {
        #[cfg(target_arch = "x86_64")]
        {
            if !is_x86_feature_detected!("avx2") {
                return; // no AVX2 here: only the scalar path exists to run
            }
            let mut rng = Sampler::for_batch(23, 0);
            let specials = [0.0, -0.0, f64::from_bits(1), -f64::from_bits(77), f64::MAX, -f64::MAX, f64::MIN_POSITIVE];
            let (mut lanes, mut scalar) = (ExactSum4::default(), [ExactSum::default(); 4]);
            let (mut fast, mut slow) = (0, 0);
            for step in 0..200_000 {
                if step % 2000 == 0 {
                    (lanes, scalar) = (ExactSum4::default(), [ExactSum::default(); 4]);
                }
                let decades = [600.0, 30.0, 3.0][step % 3];
                let mut v: [f64; 4] = values(&mut rng, 4, decades).try_into().unwrap();
                for x in v.iter_mut() {
                    let u = rng.uniform();
                    if u < 0.01 {
                        *x = specials[below(&mut rng, specials.len())];
                    } else if u < 0.01002 {
                        *x = [f64::INFINITY, f64::NEG_INFINITY, f64::NAN][below(&mut rng, 3)];
                    }
                }
                let before = lanes;
                // SAFETY: the CPU has AVX2 (checked above).
                unsafe { lanes.add_avx2(v) };
                for k in 0..4 {
                    scalar[k].add(v[k]);
                }
                assert_eq!(lanes.lanes(), scalar, "step {step}: {before:?} + {v:?}");
                if v.iter().all(|x| x.is_normal() || *x == 0.0) && before.lanes().iter().all(|s| s.top != POISONED) {
                    fast += 1;
                } else {
                    slow += 1;
                }
            }
            assert!(fast > 150_000 && slow > 1000, "{fast} added at once, {slow} lane by lane");
        }
    }

    #[test]
    fn any_order_and_grouping_gives_the_same_bits() {
        let mut rng = Sampler::for_batch(1, 0);
        for decades in [0.5, 6.0, 30.0, 300.0] {
            let mut v = values(&mut rng, 2000, decades);
            let whole = sum_of(&v);
            for _ in 0..20 {
                // Shuffle, cut into random groups, sum each group, add the groups in random order.
                for i in (1..v.len()).rev() {
                    v.swap(i, below(&mut rng, i + 1));
                }
                let mut groups = Vec::new();
                let mut start = 0;
                while start < v.len() {
                    let end = (start + 1 + below(&mut rng, 200)).min(v.len());
                    groups.push(sum_of(&v[start..end]));
                    start = end;
                }
                for i in (1..groups.len()).rev() {
                    groups.swap(i, below(&mut rng, i + 1));
                }
                let mut total = ExactSum::default();
                for g in &groups {
                    total.add_sum(g).unwrap();
                }
                assert_eq!(total, whole);
                assert_eq!(total.value().to_bits(), whole.value().to_bits());
            }
        }
    }

    #[test]
    fn within_the_window_the_sum_is_correctly_rounded() {
        // Spreads under 10^13 (2^43) keep every bit of every value: the exact sum, rounded once.
        let mut rng = Sampler::for_batch(2, 0);
        for decades in [0.1, 3.0, 12.0] {
            for scale in [1e-300, 1e-12, 1.0, 3e7, 1e290] {
                let v: Vec<f64> = values(&mut rng, 500, decades).iter().map(|x| x * scale).collect();
                assert_eq!(sum_of(&v).value(), fsum(&v), "decades {decades}, scale {scale}");
            }
        }
        // Cancellation that plain f64 addition gets wrong: 1e16 + 1 − 1e16 + 1 = 2.
        assert_eq!(sum_of(&[1e16, 1.0, -1e16, 1.0]).value(), 2.0);
        assert_eq!(sum_of(&[0.1; 10]).value(), fsum(&[0.1; 10]));
    }

    #[test]
    fn beyond_the_window_no_more_is_lost_than_by_f64_addition() {
        // One huge value and many tiny ones: the tiny ones' lost bits stay below 2^−56 of the
        // huge one each, where in-order f64 addition loses up to half an ulp (2^−53) each.
        let mut rng = Sampler::for_batch(3, 0);
        let mut v = vec![1e20];
        v.extend((0..10_000).map(|_| rng.uniform()));
        let exact = fsum(&v);
        let err = (sum_of(&v).value() - exact).abs();
        assert!(err <= v.len() as f64 * 1e20 * 2f64.powi(-56), "error {err}");
    }

    #[test]
    fn parts_match_a_wide_shift() {
        let mut rng = 0x2545_F491_4F6C_DD1Du64;
        for shift in 0..SLOT_BITS as u32 {
            for k in 0..2000 {
                rng ^= rng << 13;
                rng ^= rng >> 7;
                rng ^= rng << 17;
                // The extremes of a 53-bit significand and random ones.
                let m = match k {
                    0 => (1 << 53) - 1,
                    1 => 1 << 52,
                    2 => 1,
                    _ => rng >> 11,
                };
                let wide = (m as u128) << shift;
                let mask = (1u128 << SLOT_BITS) - 1;
                let expected =
                    ((wide & mask) as u64, ((wide >> SLOT_BITS) & mask) as u64, (wide >> (2 * SLOT_BITS)) as u64);
                assert_eq!(split_parts(m, shift), expected, "m = {m:#x}, shift = {shift}");
            }
        }
    }

    #[test]
    fn edge_values() {
        let tiny = f64::from_bits(1);
        assert_eq!(sum_of(&[tiny, tiny, tiny]).value(), 3.0 * tiny);
        // 1 lies 2^1023 below the window: dropped in every order, where f64 addition gives 1
        // (MAX − MAX + 1) or 0 ((MAX + 1) − MAX) by order.
        assert_eq!(sum_of(&[f64::MAX, -f64::MAX, 1.0]).value(), 0.0);
        assert_eq!(sum_of(&[1.0, f64::MAX, -f64::MAX]).value(), 0.0);
        assert_eq!(sum_of(&[f64::MAX / 2.0, f64::MAX / 4.0]).value(), f64::MAX * 0.75);
        assert!(sum_of(&[f64::MAX, f64::MAX]).value().is_infinite());
        assert_eq!(sum_of(&[]).value(), 0.0);
        assert_eq!(sum_of(&[0.0, -0.0]).value(), 0.0);
        assert!(sum_of(&[1.0, f64::NAN, 2.0]).value().is_nan());
        assert!(sum_of(&[1.0, f64::INFINITY]).value().is_nan());
        // Bytes round trip; a top that is no slot is refused.
        let s = sum_of(&[3.5, -1e-9, 7e30]);
        assert_eq!(ExactSum::from_bytes(&s.to_bytes()), Some(s));
        let mut bad = s.to_bytes();
        bad[..4].copy_from_slice(&100i32.to_le_bytes());
        assert_eq!(ExactSum::from_bytes(&bad), None);
    }

    #[test]
    fn a_merge_that_would_overflow_is_refused_and_changes_nothing() {
        // Words near 2^63 (more than `MAX_VALUES` values' worth): only a crafted state has them.
        let mut bytes = sum_of(&[1.0]).to_bytes();
        for k in 0..3 {
            bytes[4 + 8 * k..12 + 8 * k].copy_from_slice(&(i64::MAX - 1).to_le_bytes());
        }
        let huge = ExactSum::from_bytes(&bytes).unwrap();
        let mut total = huge;
        assert_eq!(total.add_sum(&huge), Err(Overflow));
        assert_eq!(total, huge);
        // Within the bound, merges add.
        let mut one = sum_of(&[1.0]);
        assert_eq!(one.add_sum(&sum_of(&[2.0])), Ok(()));
        assert_eq!(one.value(), 3.0);
    }
}
