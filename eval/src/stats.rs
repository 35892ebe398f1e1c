//! Summary statistics: means with Student-t 95 % confidence intervals, quantiles, and a
//! percentile bootstrap with a fixed seed (so a report is reproducible to the digit).

use serde::Serialize;

/// A mean with its 95 % confidence interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MeanCi {
    pub n: usize,
    pub mean: f64,
    pub lo: f64,
    pub hi: f64,
}

/// Mean and Student-t 95 % interval of `xs` (non-finite values are skipped); `None` when empty.
/// With one value the interval is that value.
pub fn mean_ci95(xs: &[f64]) -> Option<MeanCi> {
    let v: Vec<f64> = xs.iter().copied().filter(|x| x.is_finite()).collect();
    let n = v.len();
    if n == 0 {
        return None;
    }
    let mean = v.iter().sum::<f64>() / n as f64;
    if n == 1 {
        return Some(MeanCi {
            n,
            mean,
            lo: mean,
            hi: mean,
        });
    }
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    let half = t975(n - 1) * (var / n as f64).sqrt();
    Some(MeanCi {
        n,
        mean,
        lo: mean - half,
        hi: mean + half,
    })
}

/// The 97.5 % quantile of Student's t with `df` degrees of freedom (table to 30, then the
/// Cornish-Fisher expansion around the normal quantile, good to 1e-4).
pub fn t975(df: usize) -> f64 {
    const TABLE: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    match df {
        0 => f64::INFINITY,
        1..=30 => TABLE[df - 1],
        _ => {
            let z = 1.959_963_984_540_054f64;
            let v = df as f64;
            z + (z.powi(3) + z) / (4.0 * v)
                + (5.0 * z.powi(5) + 16.0 * z.powi(3) + 3.0 * z) / (96.0 * v * v)
                + (3.0 * z.powi(7) + 19.0 * z.powi(5) + 17.0 * z.powi(3) - 15.0 * z)
                    / (384.0 * v.powi(3))
        }
    }
}

/// The `q` quantile (0..=1) of `xs` by linear interpolation between order statistics; `None` when
/// there is no finite value.
pub fn quantile(xs: &[f64], q: f64) -> Option<f64> {
    let mut v: Vec<f64> = xs.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let pos = q.clamp(0.0, 1.0) * (v.len() - 1) as f64;
    let (i, f) = (pos.floor() as usize, pos.fract());
    Some(if i + 1 < v.len() {
        v[i] * (1.0 - f) + v[i + 1] * f
    } else {
        v[i]
    })
}

/// The median of `xs`.
pub fn median(xs: &[f64]) -> Option<f64> {
    quantile(xs, 0.5)
}

/// Percentile-bootstrap 95 % interval of `statistic` over `xs`, from `resamples` resamples drawn
/// with a fixed-seed generator; `None` when `xs` is empty.
pub fn bootstrap_ci95(
    xs: &[f64],
    resamples: usize,
    seed: u64,
    statistic: impl Fn(&[f64]) -> f64,
) -> Option<(f64, f64)> {
    if xs.is_empty() || resamples == 0 {
        return None;
    }
    let mut rng = SplitMix64(seed);
    let mut stats = Vec::with_capacity(resamples);
    let mut sample = vec![0.0; xs.len()];
    for _ in 0..resamples {
        for s in sample.iter_mut() {
            *s = xs[(rng.next_u64() % xs.len() as u64) as usize];
        }
        stats.push(statistic(&sample));
    }
    Some((quantile(&stats, 0.025)?, quantile(&stats, 0.975)?))
}

/// A small, fast, seeded generator (SplitMix64); enough for resampling indices.
#[derive(Debug, Clone)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_interval_of_known_data() {
        // 1..=5: mean 3, sd sqrt(2.5), t(4) = 2.776 → half width 2.776 * sqrt(0.5).
        let ci = mean_ci95(&[1.0, 2.0, 3.0, 4.0, 5.0]).unwrap();
        assert_eq!(ci.mean, 3.0);
        assert!((ci.hi - ci.mean - 2.776 * 0.5f64.sqrt()).abs() < 1e-9);
        assert_eq!(mean_ci95(&[]), None);
        assert_eq!(mean_ci95(&[2.0]).unwrap().lo, 2.0);
    }

    #[test]
    fn t_quantile_joins_the_table_smoothly() {
        assert!((t975(31) - 2.0395).abs() < 1e-3, "{}", t975(31));
        assert!((t975(60) - 2.0003).abs() < 1e-3);
        assert!((t975(100_000) - 1.96).abs() < 1e-3);
        assert!(t975(29) > t975(30) && t975(30) > t975(31));
    }

    #[test]
    fn quantiles_interpolate() {
        let xs = [4.0, 1.0, 3.0, 2.0];
        assert_eq!(median(&xs), Some(2.5));
        assert_eq!(quantile(&xs, 0.0), Some(1.0));
        assert_eq!(quantile(&xs, 1.0), Some(4.0));
        assert_eq!(median(&[f64::NAN]), None);
    }

    #[test]
    fn bootstrap_is_reproducible_and_brackets_the_mean() {
        let xs: Vec<f64> = (0..200).map(|i| f64::from(i % 17)).collect();
        let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
        let a = bootstrap_ci95(&xs, 500, 42, mean).unwrap();
        let b = bootstrap_ci95(&xs, 500, 42, mean).unwrap();
        assert_eq!(a, b);
        let m = mean(&xs);
        assert!(a.0 < m && m < a.1, "{a:?} {m}");
        let t = mean_ci95(&xs).unwrap();
        assert!(
            (a.0 - t.lo).abs() < 0.3 && (a.1 - t.hi).abs() < 0.3,
            "{a:?} {t:?}"
        );
    }
}
