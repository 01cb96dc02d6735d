//! Numeric helpers shared by the scores and the report: numpy's mean (same summation order, so
//! that averaged scores agree with bop_toolkit to the last bit) and bop_toolkit's recall.

/// bop_toolkit's `calc_recall`: 0 when there is nothing to find.
pub fn recall(tp: usize, targets: usize) -> f64 {
    if targets == 0 {
        0.0
    } else {
        tp as f64 / targets as f64
    }
}

/// The arithmetic mean with numpy's pairwise summation (`np.mean`), so that averaged scores
/// agree with the reference bit for bit. Empty input gives NaN, as in numpy.
pub fn mean(values: &[f64]) -> f64 {
    pairwise_sum(values) / values.len() as f64
}

fn pairwise_sum(a: &[f64]) -> f64 {
    const BLOCK: usize = 128;
    let n = a.len();
    if n < 8 {
        let mut s = 0.0;
        for &v in a {
            s += v;
        }
        s
    } else if n <= BLOCK {
        let mut r = [0.0f64; 8];
        r.copy_from_slice(&a[..8]);
        let mut i = 8;
        while i < n - n % 8 {
            for j in 0..8 {
                r[j] += a[i + j];
            }
            i += 8;
        }
        let mut s = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for &v in &a[i..] {
            s += v;
        }
        s
    } else {
        let mut half = n / 2;
        half -= half % 8;
        pairwise_sum(&a[..half]) + pairwise_sum(&a[half..])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_follows_numpy_summation_order() {
        // 0.1 summed ten times sequentially is 0.9999999999999999; numpy's blocked sum gives 1.0.
        let tenths = vec![0.1; 10];
        assert_eq!(mean(&tenths), 0.1);
        let mut seq = 0.0;
        for v in &tenths {
            seq += v;
        }
        assert_ne!(seq / 10.0, mean(&tenths));
        assert_eq!(mean(&[1.0, 2.0]), 1.5);
        assert!(mean(&[]).is_nan());
        let many: Vec<f64> = (0..1000).map(|i| i as f64).collect();
        assert_eq!(mean(&many), 499.5);
    }

    #[test]
    fn numpy_summation_order() {
        let a: Vec<f64> = (0..300).map(|i| 0.1 * i as f64 + 1e-3).collect();
        // Small arrays: left to right.
        assert_eq!(
            pairwise_sum(&a[..5]),
            (((a[0] + a[1]) + a[2]) + a[3]) + a[4]
        );
        // 8..=128: eight accumulators, then the tail.
        let nine = pairwise_sum(&a[..9]);
        let r = &a[..8];
        assert_eq!(
            nine,
            ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7])) + a[8]
        );
        // Large arrays: split at a multiple of 8.
        assert_eq!(
            pairwise_sum(&a),
            pairwise_sum(&a[..144]) + pairwise_sum(&a[144..])
        );
        assert_eq!(pairwise_sum(&[]), 0.0);
    }

    #[test]
    fn recall_of_nothing_is_zero() {
        assert_eq!(recall(0, 0), 0.0);
        assert_eq!(recall(3, 4), 0.75);
    }
}
