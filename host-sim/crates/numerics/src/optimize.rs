//! One-dimensional minimisation for the discovery's nonlinear parameters (time constants, line
//! frequencies, noise levels): a fixed number of golden-section steps, so that the cost is
//! known and the result does not depend on a tolerance.

/// The minimiser of a unimodal `f` on [a, b] after `iters` golden-section steps (the bracket
/// shrinks by 0.618 per step); the better of the two last interior points.
pub fn golden_section_min<F: Fn(f64) -> f64>(f: F, mut a: f64, mut b: f64, iters: usize) -> f64 {
    let g = 0.618_033_988_749_895;
    let mut c = b - g * (b - a);
    let mut d = a + g * (b - a);
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..iters {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = f(d);
        }
    }
    if fc < fd {
        c
    } else {
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_minimum_of_a_parabola_to_the_bracket_width() {
        let x = golden_section_min(|x| (x - 0.3).powi(2), -1.0, 2.0, 40);
        // 3 · 0.618^40 ≈ 1.3e-8.
        assert!((x - 0.3).abs() < 2e-8, "{x}");
    }
}
