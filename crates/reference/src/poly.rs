//! Real roots of small polynomials by derivative recursion: the roots of `p'` split the
//! interval into pieces where `p` is monotone, and each piece with a sign change holds
//! exactly one root, found by bisection to the last bit. No closed-form quartic formula,
//! so no catastrophic cancellation; double roots (tangent rays) are found where `|p|`
//! vanishes at a root of `p'`.

/// Evaluates `c[0] + c[1] x + ... + c[n] x^n` (Horner).
pub fn eval(c: &[f64], x: f64) -> f64 {
    c.iter().rev().fold(0.0, |acc, &k| acc * x + k)
}

fn derivative(c: &[f64]) -> Vec<f64> {
    c.iter()
        .enumerate()
        .skip(1)
        .map(|(i, &k)| k * i as f64)
        .collect()
}

/// Bisection of a bracketed sign change of `p` on `[lo, hi]` down to adjacent floats.
fn bisect(c: &[f64], mut lo: f64, mut hi: f64) -> f64 {
    let mut flo = eval(c, lo);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        let fm = eval(c, mid);
        if fm == 0.0 {
            return mid;
        }
        if (fm < 0.0) == (flo < 0.0) {
            lo = mid;
            flo = fm;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The real roots of the polynomial `c` (coefficients, lowest degree first) in `[lo, hi]`,
/// ascending. `touch_tol` is the magnitude below which a local extremum counts as a double
/// root (a tangency); pass 0 to ignore tangencies.
pub fn real_roots(c: &[f64], lo: f64, hi: f64, touch_tol: f64) -> Vec<f64> {
    let mut c = c.to_vec();
    while c.len() > 1 && c[c.len() - 1] == 0.0 {
        c.pop();
    }
    if c.len() <= 1 || lo > hi {
        return Vec::new();
    }
    if c.len() == 2 {
        let x = -c[0] / c[1];
        return if x >= lo && x <= hi {
            vec![x]
        } else {
            Vec::new()
        };
    }
    let crit = real_roots(&derivative(&c), lo, hi, 0.0);
    let mut knots = Vec::with_capacity(crit.len() + 2);
    knots.push(lo);
    knots.extend(crit.iter().copied());
    knots.push(hi);
    let mut roots: Vec<f64> = Vec::new();
    for w in knots.windows(2) {
        let (a, b) = (w[0], w[1]);
        let (fa, fb) = (eval(&c, a), eval(&c, b));
        if fa == 0.0 {
            if roots.last() != Some(&a) {
                roots.push(a);
            }
        } else if (fa < 0.0) != (fb < 0.0) && fb != 0.0 {
            roots.push(bisect(&c, a, b));
        }
    }
    let fh = eval(&c, hi);
    if fh == 0.0 && roots.last() != Some(&hi) {
        roots.push(hi);
    }
    if touch_tol > 0.0 {
        for &x in &crit {
            if eval(&c, x).abs() <= touch_tol
                && !roots
                    .iter()
                    .any(|&r| (r - x).abs() <= 1e-12 * (1.0 + x.abs()))
            {
                roots.push(x);
            }
        }
        roots.sort_by(f64::total_cmp);
    }
    roots
}

#[cfg(test)]
mod tests {
    use super::*;

    fn from_roots(r: &[f64]) -> Vec<f64> {
        let mut c = vec![1.0];
        for &x in r {
            let mut n = vec![0.0; c.len() + 1];
            for (i, &k) in c.iter().enumerate() {
                n[i] -= k * x;
                n[i + 1] += k;
            }
            c = n;
        }
        c
    }

    #[test]
    fn finds_four_distinct_roots() {
        let c = from_roots(&[-2.0, -0.5, 0.25, 3.0]);
        let r = real_roots(&c, -10.0, 10.0, 0.0);
        assert_eq!(r.len(), 4);
        for (a, b) in r.iter().zip([-2.0, -0.5, 0.25, 3.0]) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
    }

    #[test]
    fn respects_the_interval_and_complex_pairs() {
        // (x^2 + 1)(x - 1)(x - 5): only 1 in [0, 2].
        let c = from_roots(&[1.0, 5.0]);
        let c = [c[0], c[1], c[2] + c[0], c[1], c[2]];
        assert_eq!(real_roots(&c, 0.0, 2.0, 0.0).len(), 1);
    }

    #[test]
    fn double_root_found_with_touch_tolerance() {
        // A tangency at 0.1 (not representable, so p never vanishes exactly there).
        let c = from_roots(&[0.1, 0.1, 4.0, 6.0]);
        let r = real_roots(&c, 0.0, 10.0, 1e-9);
        assert!(r.iter().any(|x| (x - 0.1).abs() < 1e-6), "{r:?}");
        assert!(r.iter().any(|x| (x - 4.0).abs() < 1e-12), "{r:?}");
        assert!(r.iter().any(|x| (x - 6.0).abs() < 1e-12), "{r:?}");
        // Without it, the simple roots are still exact.
        let r = real_roots(&c, 1.0, 10.0, 0.0);
        assert_eq!(r.len(), 2);
    }
}
