//! Shared numerics: a Nelder-Mead minimiser with a convergence report, a small deterministic
//! PRNG, medians and percentiles. One implementation of each for the whole workspace.

/// Percentile `q` (0-100) of sorted values with linear interpolation (numpy's default).
/// NaN for an empty slice.
pub fn percentile_sorted(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let pos = q / 100.0 * (sorted.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    let frac = pos - lo as f64;
    if lo == hi {
        sorted[lo]
    } else {
        sorted[lo] + (sorted[hi] - sorted[lo]) * frac
    }
}

/// Median of finite values (mean of the two middle ones for an even count); `None` when empty.
pub fn median(values: &[f64]) -> Option<f64> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| !x.is_nan()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    })
}

/// The finite values with a finite positive weight, as `(value, weight)` sorted by value, and
/// their total weight; `None` when there are none.
fn sorted_weighted(values: &[f64], weights: &[f64]) -> Option<(Vec<(f64, f64)>, f64)> {
    let mut pairs: Vec<(f64, f64)> = values
        .iter()
        .zip(weights)
        .filter(|(v, w)| v.is_finite() && w.is_finite() && **w > 0.0)
        .map(|(v, w)| (*v, *w))
        .collect();
    if pairs.is_empty() {
        return None;
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total = pairs.iter().map(|p| p.1).sum();
    Some((pairs, total))
}

/// Weighted median: a minimiser of `Σ w_i |x - x_i|` (the lower one when the minimum is a
/// segment). `None` when empty or when no weight is positive.
pub fn weighted_median(values: &[f64], weights: &[f64]) -> Option<f64> {
    let (pairs, total) = sorted_weighted(values, weights)?;
    let mut acc = 0.0;
    for (v, w) in &pairs {
        acc += w;
        if acc >= total / 2.0 {
            return Some(*v);
        }
    }
    pairs.last().map(|p| p.0)
}

/// The shorth: the weighted mean of the densest half of `values`, the shortest interval
/// holding at least half the total weight (Andrews et al. 1972). Like the median it ignores
/// anything outside that half; unlike it, a one-sided tail of up to half the weight (vans and
/// trucks among cars) moves it only as far as the tail reaches into the densest half. `None`
/// when empty or when no weight is positive.
pub fn weighted_shorth(values: &[f64], weights: &[f64]) -> Option<f64> {
    let (pairs, total) = sorted_weighted(values, weights)?;
    // Two pointers: for each start i, the first end j whose window holds half the weight.
    let (mut best, mut j, mut inside) = (None::<(f64, usize, usize)>, 0, 0.0);
    for i in 0..pairs.len() {
        while inside < total / 2.0 && j < pairs.len() {
            inside += pairs[j].1;
            j += 1;
        }
        if inside < total / 2.0 {
            break;
        }
        let width = pairs[j - 1].0 - pairs[i].0;
        if best.is_none_or(|b| width < b.0) {
            best = Some((width, i, j));
        }
        inside -= pairs[i].1;
    }
    let (_, i, j) = best?;
    let half = &pairs[i..j];
    let w: f64 = half.iter().map(|p| p.1).sum();
    Some(half.iter().map(|p| p.0 * p.1).sum::<f64>() / w)
}

/// Percentile `q` (0-100) of unsorted values, as [`percentile_sorted`].
pub fn percentile(mut v: Vec<f64>, q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    percentile_sorted(&v, q)
}

/// Half the range between the 16th and 84th percentiles of `v`: a normal's standard
/// deviation that the few values far out (bootstrap refits settled in another valley) do not
/// decide. NaN for an empty slice.
pub fn half_p16_p84(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    0.5 * (percentile_sorted(&v, 84.0) - percentile_sorted(&v, 16.0))
}

/// Population standard deviation (NaN for an empty slice).
pub fn sd(v: &[f64]) -> f64 {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / n).sqrt()
}

/// A small deterministic PRNG (SplitMix64), so that the geometry crate needs no dependency.
#[derive(Debug, Clone)]
pub struct SplitMix(pub u64);

impl SplitMix {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// A standard normal deviate (Box-Muller, one of the pair).
    pub fn normal(&mut self) -> f64 {
        let u1 = self.next_f64().max(f64::MIN_POSITIVE);
        let u2 = self.next_f64();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
    /// Poisson(1) count (inverse transform).
    pub fn poisson1(&mut self) -> f64 {
        let u = self.next_f64();
        let mut k = 0.0;
        let mut p = (-1.0f64).exp();
        let mut cdf = p;
        while u > cdf && k < 20.0 {
            k += 1.0;
            p /= k;
            cdf += p;
        }
        k
    }
}

/// `f` of each item, in the items' order, the items split into one contiguous run per core.
///
/// The result is the same as `items.iter().map(f)` whatever the number of cores, so a
/// caller stays deterministic as long as `f` is (draw the random numbers before, in order).
pub fn par_map<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let threads = cores.min(items.len());
    if threads <= 1 {
        return items.iter().map(f).collect();
    }
    let chunk = items.len().div_ceil(threads);
    let f = &f;
    std::thread::scope(|s| {
        let handles: Vec<_> = items
            .chunks(chunk)
            .map(|run| s.spawn(move || run.iter().map(f).collect::<Vec<R>>()))
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    })
}

/// The result of [`nelder_mead`].
#[derive(Debug, Clone, PartialEq)]
pub struct Minimum {
    /// The best point found.
    pub x: Vec<f64>,
    /// `f(x)`.
    pub value: f64,
    /// Iterations used.
    pub iterations: usize,
    /// Whether the simplex's values agreed to the tolerance before the iteration budget ran out.
    pub converged: bool,
}

/// Relative spread of the simplex's values at which [`nelder_mead`] stops.
pub const NELDER_MEAD_TOLERANCE: f64 = 1e-10;

/// Minimise `f` from `x0` with initial steps `step` (Nelder-Mead with the standard
/// coefficients: reflection 1, expansion 2, contraction 0.5, shrink 0.5), at most `iters`
/// iterations; stops when the simplex's values agree to [`NELDER_MEAD_TOLERANCE`] relative.
pub fn nelder_mead(f: impl Fn(&[f64]) -> f64, x0: &[f64], step: &[f64], iters: usize) -> Minimum {
    let n = x0.len();
    let mut simplex: Vec<(Vec<f64>, f64)> = Vec::with_capacity(n + 1);
    simplex.push((x0.to_vec(), f(x0)));
    for i in 0..n {
        let mut x = x0.to_vec();
        x[i] += step[i];
        let v = f(&x);
        simplex.push((x, v));
    }
    let mut iterations = 0;
    let mut converged = false;
    while iterations < iters {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        let spread = (simplex[n].1 - simplex[0].1).abs();
        if spread <= NELDER_MEAD_TOLERANCE * (1.0 + simplex[0].1.abs()) {
            converged = true;
            break;
        }
        iterations += 1;
        let mut centroid = vec![0.0; n];
        for (x, _) in &simplex[..n] {
            for (c, xi) in centroid.iter_mut().zip(x) {
                *c += xi / n as f64;
            }
        }
        let along = |t: f64| -> Vec<f64> {
            centroid
                .iter()
                .zip(&simplex[n].0)
                .map(|(c, w)| c + t * (w - c))
                .collect()
        };
        let xr = along(-1.0);
        let fr = f(&xr);
        if fr < simplex[0].1 {
            let xe = along(-2.0);
            let fe = f(&xe);
            simplex[n] = if fe < fr { (xe, fe) } else { (xr, fr) };
        } else if fr < simplex[n - 1].1 {
            simplex[n] = (xr, fr);
        } else {
            let xc = if fr < simplex[n].1 {
                along(-0.5)
            } else {
                along(0.5)
            };
            let fc = f(&xc);
            if fc < fr.min(simplex[n].1) {
                simplex[n] = (xc, fc);
            } else {
                let best = simplex[0].0.clone();
                for s in simplex.iter_mut().skip(1) {
                    s.0 =
                        s.0.iter()
                            .zip(&best)
                            .map(|(x, b)| b + 0.5 * (x - b))
                            .collect();
                    s.1 = f(&s.0);
                }
            }
        }
    }
    simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
    let (x, value) = simplex.swap_remove(0);
    Minimum {
        x,
        value,
        iterations,
        converged,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn par_map_keeps_the_order_of_the_items() {
        let items: Vec<u64> = (0..1001).collect();
        let got = par_map(&items, |&x| x * x + 1);
        let want: Vec<u64> = items.iter().map(|&x| x * x + 1).collect();
        assert_eq!(got, want);
        assert!(par_map(&[] as &[u64], |&x| x).is_empty());
        assert_eq!(par_map(&[7u64], |&x| x + 1), vec![8]);
    }

    #[test]
    fn nelder_mead_finds_the_minimum_of_the_rosenbrock_valley() {
        let rosen = |x: &[f64]| (1.0 - x[0]).powi(2) + 100.0 * (x[1] - x[0] * x[0]).powi(2);
        let m = nelder_mead(rosen, &[-1.2, 1.0], &[0.1, 0.1], 2000);
        assert!(m.converged, "{m:?}");
        assert!(
            (m.x[0] - 1.0).abs() < 1e-3 && (m.x[1] - 1.0).abs() < 1e-3,
            "{m:?}"
        );
        assert!(m.value < 1e-6 && m.iterations < 2000);
        // Too small a budget: the report says so.
        let short = nelder_mead(rosen, &[-1.2, 1.0], &[0.1, 0.1], 5);
        assert!(!short.converged && short.iterations == 5);
        assert!(short.value <= rosen(&[-1.2, 1.0]));
    }

    #[test]
    fn nelder_mead_on_a_quadratic_bowl_in_three_dimensions() {
        let bowl =
            |x: &[f64]| (x[0] - 3.0).powi(2) + 2.0 * (x[1] + 1.0).powi(2) + 0.5 * x[2] * x[2];
        let m = nelder_mead(bowl, &[0.0, 0.0, 0.0], &[1.0, 1.0, 1.0], 1000);
        assert!(m.converged);
        for (got, want) in m.x.iter().zip([3.0, -1.0, 0.0]) {
            assert!((got - want).abs() < 1e-3, "{m:?}");
        }
    }

    #[test]
    fn splitmix_is_deterministic_and_uniform() {
        let mut a = SplitMix(7);
        let mut b = SplitMix(7);
        let xs: Vec<f64> = (0..10_000).map(|_| a.next_f64()).collect();
        assert!(xs
            .iter()
            .zip((0..10_000).map(|_| b.next_f64()))
            .all(|(x, y)| *x == y));
        assert!(xs.iter().all(|x| (0.0..1.0).contains(x)));
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        assert!((mean - 0.5).abs() < 0.01, "{mean}");
        let p: Vec<f64> = (0..20_000).map(|_| a.poisson1()).collect();
        let mean = p.iter().sum::<f64>() / p.len() as f64;
        assert!((mean - 1.0).abs() < 0.03, "{mean}");
    }

    #[test]
    fn the_shorth_stays_on_the_cluster_a_one_sided_tail_moves_the_median_off() {
        // 60 cars spread evenly over ln size -0.05..0.05, 40 vans and trucks at 0.2..0.6.
        let cars = (0..60).map(|i| -0.05 + 0.1 * f64::from(i) / 59.0);
        let large = (0..40).map(|i| 0.2 + 0.4 * f64::from(i) / 39.0);
        let v: Vec<f64> = cars.chain(large).collect();
        let ones = vec![1.0; v.len()];
        let shorth = weighted_shorth(&v, &ones).unwrap();
        let median = weighted_median(&v, &ones).unwrap();
        assert!(shorth.abs() < 0.02, "{shorth}");
        assert!(median > 0.03, "{median}");
        // Weights count as copies: weight 2 on one value is that value twice.
        let w: Vec<f64> = (0..v.len())
            .map(|i| if i == 99 { 2.0 } else { 1.0 })
            .collect();
        let mut twice = v.clone();
        twice.push(v[99]);
        let a = weighted_shorth(&v, &w).unwrap();
        let b = weighted_shorth(&twice, &vec![1.0; twice.len()]).unwrap();
        assert!((a - b).abs() < 1e-12, "{a} {b}");
        assert_eq!(weighted_shorth(&[], &[]), None);
        assert_eq!(weighted_shorth(&[1.0, 2.0], &[0.0, 0.0]), None);
        assert_eq!(weighted_shorth(&[3.0], &[1.0]), Some(3.0));
    }

    proptest::proptest! {
        #[test]
        fn the_shorth_lies_in_the_data_and_moves_with_it(
            v in proptest::collection::vec(-10.0f64..10.0, 1..60),
            shift in -5.0f64..5.0,
        ) {
            let ones = vec![1.0; v.len()];
            let s = weighted_shorth(&v, &ones).unwrap();
            let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            proptest::prop_assert!(s >= lo - 1e-9 && s <= hi + 1e-9);
            let moved: Vec<f64> = v.iter().map(|x| x + shift).collect();
            let t = weighted_shorth(&moved, &ones).unwrap();
            proptest::prop_assert!((t - s - shift).abs() < 1e-6, "{} {} {}", s, t, shift);
        }
    }

    #[test]
    fn medians_and_percentiles() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), Some(2.5));
        assert_eq!(median(&[f64::NAN, 1.0]), Some(1.0));
        assert_eq!(median(&[]), None);
        assert_eq!(
            weighted_median(&[1.0, 2.0, 10.0], &[1.0, 1.0, 5.0]),
            Some(10.0)
        );
        assert_eq!(percentile(vec![1.0, 2.0, 3.0, 4.0], 50.0), 2.5);
        assert_eq!(percentile_sorted(&[0.0, 10.0], 25.0), 2.5);
        assert!(percentile(Vec::new(), 50.0).is_nan());
        assert!((sd(&[1.0, 3.0]) - 1.0).abs() < 1e-15);
    }
}
