//! Distribution and special functions of the host's statistics (fit's F and t tests, the Allan
//! deviations' ln Γ), from `statrs`. The tests below are the precision tests that decided it:
//! closed forms to 1e-13 and printed table values (docs/numerics.md, "Host numerics").

use statrs::distribution::{ChiSquared, ContinuousCDF, FisherSnedecor, StudentsT};
use statrs::function::{beta, gamma};
use thiserror::Error;

/// Why a special-function value could not be computed.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum SpecialError {
    /// a or b ≤ 0, x outside [0, 1], or a NaN.
    #[error("incomplete beta: argument out of domain (a={a}, b={b}, x={x})")]
    Domain {
        /// Shape a.
        a: f64,
        /// Shape b.
        b: f64,
        /// Argument x.
        x: f64,
    },
    /// The continued fraction did not converge in the iteration budget.
    #[error("incomplete beta: continued fraction did not converge (a={a}, b={b}, x={x})")]
    NoConvergence {
        /// Shape a.
        a: f64,
        /// Shape b.
        b: f64,
        /// Argument x.
        x: f64,
    },
}

/// ln Γ(z) for z > 0 (statrs: Lanczos, relative error ≲ 1e-15).
pub fn ln_gamma(z: f64) -> f64 {
    gamma::ln_gamma(z)
}

/// The regularized incomplete beta function I_x(a, b) = B(x; a, b) / B(a, b).
pub fn incomplete_beta(a: f64, b: f64, x: f64) -> Result<f64, SpecialError> {
    if !(a > 0.0 && b > 0.0 && (0.0..=1.0).contains(&x)) {
        return Err(SpecialError::Domain { a, b, x });
    }
    beta::checked_beta_reg(a, b, x).map_err(|_| SpecialError::Domain { a, b, x })
}

/// Upper tail P(F > f) of the F distribution with (d1, d2) degrees of freedom.
pub fn f_upper_tail(f: f64, d1: f64, d2: f64) -> Result<f64, SpecialError> {
    if f.is_nan() {
        return Err(SpecialError::Domain { a: d1, b: d2, x: f });
    }
    if f <= 0.0 {
        return Ok(1.0);
    }
    if f.is_infinite() {
        return Ok(0.0);
    }
    let dist =
        FisherSnedecor::new(d1, d2).map_err(|_| SpecialError::Domain { a: d1, b: d2, x: f })?;
    Ok(dist.sf(f))
}

/// Two-sided P(|T| > t) of Student's t distribution with ν degrees of freedom.
pub fn t_two_sided(t: f64, nu: f64) -> Result<f64, SpecialError> {
    if t.is_nan() {
        return Err(SpecialError::Domain {
            a: nu,
            b: 0.5,
            x: t,
        });
    }
    if t.is_infinite() {
        return Ok(0.0);
    }
    let dist = StudentsT::new(0.0, 1.0, nu).map_err(|_| SpecialError::Domain {
        a: nu,
        b: 0.5,
        x: t,
    })?;
    Ok(2.0 * dist.sf(t.abs()))
}

/// Quantile of the chi-squared distribution with `nu` (> 0, real) degrees of freedom: statrs'
/// safeguarded Newton iteration on the regularized incomplete gamma function. NaN when p is not
/// in (0, 1) or ν ≤ 0.
pub fn chi2_quantile(p: f64, nu: f64) -> f64 {
    if !(p > 0.0 && p < 1.0 && nu > 0.0) {
        return f64::NAN;
    }
    ChiSquared::new(nu).map_or(f64::NAN, |d| d.inverse_cdf(p))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ln_gamma_matches_factorials_and_sqrt_pi() {
        // Γ(n) = (n − 1)!, Γ(1/2) = √π.
        let mut fact = 1.0_f64;
        for n in 1..20 {
            assert!((ln_gamma(f64::from(n)) - fact.ln()).abs() < 1e-12, "n={n}");
            fact *= f64::from(n);
        }
        assert!((ln_gamma(0.5) - std::f64::consts::PI.sqrt().ln()).abs() < 1e-14);
        assert!((ln_gamma(0.25) - 3.625_609_908_221_908_f64.ln()).abs() < 1e-13);
    }

    #[test]
    fn incomplete_beta_matches_its_closed_forms() {
        // I_x(a, 1) = x^a, I_x(1, b) = 1 − (1 − x)^b, I_x(1/2, 1/2) = (2/π)·asin(√x).
        for x in [0.01, 0.2, 0.5, 0.77, 0.999] {
            for a in [0.5, 1.0, 2.5, 7.0] {
                assert!((incomplete_beta(a, 1.0, x).unwrap() - x.powf(a)).abs() < 1e-13);
                let want = 1.0 - (1.0 - x).powf(a);
                assert!((incomplete_beta(1.0, a, x).unwrap() - want).abs() < 1e-13);
            }
            let arcsine = 2.0 / std::f64::consts::PI * x.sqrt().asin();
            assert!((incomplete_beta(0.5, 0.5, x).unwrap() - arcsine).abs() < 1e-13);
        }
    }

    #[test]
    fn f_tail_reproduces_printed_critical_values() {
        // Printed F tables (4–5 significant digits): F(1,5) 5 % → 6.608, 1 % → 16.258;
        // F(1,10) 5 % → 4.965; F(2,10) 5 % → 4.103; F(3,4) 5 % → 6.591. The rounding of the
        // table entry moves p by < 1e-4 at these slopes.
        for (f, d1, d2, p) in [
            (6.608, 1.0, 5.0, 0.05),
            (16.258, 1.0, 5.0, 0.01),
            (4.965, 1.0, 10.0, 0.05),
            (4.103, 2.0, 10.0, 0.05),
            (6.591, 3.0, 4.0, 0.05),
        ] {
            let got = f_upper_tail(f, d1, d2).unwrap();
            assert!((got - p).abs() < 1e-4, "F({d1},{d2}) at {f}: {got}");
        }
        assert_eq!(f_upper_tail(0.0, 1.0, 5.0), Ok(1.0));
        assert_eq!(f_upper_tail(f64::INFINITY, 1.0, 5.0), Ok(0.0));
    }

    #[test]
    fn t_tail_matches_tables_and_the_cauchy_and_nu2_closed_forms() {
        // Two-sided 5 % points: ν=10 → 2.228, ν=5 → 2.571, ν=30 → 2.042.
        for (t, nu) in [(2.228, 10.0), (2.571, 5.0), (2.042, 30.0)] {
            assert!((t_two_sided(t, nu).unwrap() - 0.05).abs() < 1e-4);
        }
        for t in [0.1, 1.0, 3.0, 40.0] {
            // ν = 1 (Cauchy): p = 1 − (2/π)·atan t; ν = 2: p = 1 − t/√(2 + t²).
            let cauchy = 1.0 - 2.0 / std::f64::consts::PI * f64::atan(t);
            assert!((t_two_sided(t, 1.0).unwrap() - cauchy).abs() < 1e-13);
            let nu2 = 1.0 - t / (2.0 + t * t).sqrt();
            assert!((t_two_sided(t, 2.0).unwrap() - nu2).abs() < 1e-13);
        }
    }

    #[test]
    fn out_of_domain_arguments_are_named_errors() {
        assert!(matches!(
            incomplete_beta(-1.0, 1.0, 0.5),
            Err(SpecialError::Domain { .. })
        ));
        assert!(matches!(
            incomplete_beta(1.0, 1.0, 1.5),
            Err(SpecialError::Domain { .. })
        ));
        assert!(f_upper_tail(f64::NAN, 1.0, 5.0).is_err());
    }
}
