//! From the chosen models to a calibration table (the board's defaults for what a fit cannot
//! know), and the calibration date.

use super::*;
use accomp::model::CrossAxis;
use accomp::table::Orientation;
use accomp::units::Gs;

/// Why a calibration table cannot be built from the fits.
#[derive(Debug, Error)]
pub enum BuildError {
    /// A coefficient the table cannot do without is not in the input.
    #[error("the input has no `{0}` column, which the calibration table requires")]
    MissingColumn(&'static str),
    /// The temperature scale is unusable.
    #[error("temperature range unusable: {0:?}")]
    Scale(accomp::poly::ScaleError),
    /// T0 outside the calibrated range (the core would clamp every compensation to the edge).
    #[error("--reference {t0_c} °C lies outside the calibrated range {min_c}–{max_c} °C")]
    ReferenceOutsideRange {
        /// Requested T0.
        t0_c: f64,
        /// Lowest table temperature.
        min_c: f64,
        /// Highest table temperature.
        max_c: f64,
    },
    /// The assembled table fails the core's validation (the firmware would refuse it too).
    #[error("calibration table refused by the core validator: {0:?}")]
    Table(TableError),
    /// `--date` is not YYYY-MM-DD.
    #[error("--date `{0}` is not a date of the form YYYY-MM-DD")]
    Date(String),
    /// `--orientation` is neither a named test nor three finite components.
    #[error("--orientation `{0}`: use 1g, 0g or a_i,a_p,a_o in g (e.g. 0,1,0)")]
    Orientation(String),
}

/// The test orientation stored in the table: `1g` (input axis vertical: a_i = 1 g), `0g` (input
/// axis horizontal, the dividing head's spindle along the output axis so gravity lies on the
/// pendulum axis: a_i = 0, a_p = 1 g, as in the `paper-0g` scenario) or the three components
/// `a_i,a_p,a_o` in g.
pub fn parse_orientation(text: &str) -> Result<Orientation, BuildError> {
    let err = || BuildError::Orientation(text.to_owned());
    let (a_i, a_p, a_o) = match text.trim() {
        "1g" => (1.0, 0.0, 0.0),
        "0g" => (0.0, 1.0, 0.0),
        other => {
            let v: Vec<f64> = other
                .split(',')
                .map(|x| x.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|_| err())?;
            match v.as_slice() {
                [i, p, o] if v.iter().all(|x| x.is_finite()) => (*i, *p, *o),
                _ => return Err(err()),
            }
        }
    };
    Ok(Orientation {
        cross: CrossAxis {
            a_p: Gs(a_p),
            a_o: Gs(a_o),
        },
        nominal_input: Gs(a_i),
    })
}

/// Defaults of the non-thermal table fields, which the fit cannot know. They describe the
/// reference board (docs/fitting.md): IEC 60751 Pt100, 5.11 kΩ RTD reference resistor, AD7124
/// PGA 16, 1 kΩ sense resistor (K1 ≈ 1.33 V/g), tiltmeter 10 "/V with φ0 = 0 on the input axis,
/// unit ADC gain corrections and zero offsets, orientation a_i = 1 g with no cross-axis input
/// (the paper's 1 g stability test).
pub mod defaults {
    pub use accomp::reference::board::{
        RTD_PGA_GAIN, RTD_REFERENCE_OHMS, SENSE_RESISTOR_OHMS, TILT_SCALE_ARCSEC_PER_V,
    };
    /// Nominal input of the test, g.
    pub const NOMINAL_INPUT_G: f64 = 1.0;
}

/// A calibration table from the selected order of every known column. δ columns in arcmin are
/// converted to radians here, once. K0 and K1 are required; K2, δp, δo default to zero.
pub fn calibration_table(
    report: &FitReport,
    scale: TemperatureScale,
    reference: Celsius,
    serial: &str,
    date: CalibrationDate,
) -> Result<CalibrationTable, BuildError> {
    if !(scale.min.0..=scale.max.0).contains(&reference.0) {
        return Err(BuildError::ReferenceOutsideRange {
            t0_c: reference.0,
            min_c: scale.min.0,
            max_c: scale.max.0,
        });
    }
    let poly = |column: &str| -> Option<TempPoly> {
        report
            .coefficients
            .iter()
            .find(|c| c.name == column)
            .and_then(ColumnFit::selected)
            .and_then(|m| TempPoly::from_coeffs(&m.coeffs_x))
    };
    let required = |column: &'static str| poly(column).ok_or(BuildError::MissingColumn(column));
    let models = CoefficientModels {
        bias_g: required(BIAS_COLUMN)?,
        scale_factor_v_per_g: required(SCALE_FACTOR_COLUMN)?,
        nonlinearity_g_per_g2: poly(NONLINEARITY_COLUMN).unwrap_or_default(),
        misalignment_p_rad: poly(MISALIGNMENT_P_COLUMN)
            .unwrap_or_default()
            .scaled(RAD_PER_ARCMIN),
        misalignment_o_rad: poly(MISALIGNMENT_O_COLUMN)
            .unwrap_or_default()
            .scaled(RAD_PER_ARCMIN),
    };
    let table = CalibrationTable::with_board_defaults(
        serial,
        date,
        ThermalCompensator {
            scale,
            reference,
            models,
        },
    );
    table.validate().map_err(BuildError::Table)?;
    Ok(table)
}

/// Parses `YYYY-MM-DD`.
pub fn parse_date(text: &str) -> Result<CalibrationDate, BuildError> {
    let err = || BuildError::Date(text.to_owned());
    // jiff parses the ISO 8601 date and refuses days that do not exist (2017-02-29).
    let date: jiff::civil::Date = text.trim().parse().map_err(|_| err())?;
    calibration_date(date).ok_or_else(err)
}

/// A jiff date as the table stores it (years 0..=65535).
fn calibration_date(date: jiff::civil::Date) -> Option<CalibrationDate> {
    Some(CalibrationDate {
        year: u16::try_from(date.year()).ok()?,
        month: u8::try_from(date.month()).ok()?,
        day: u8::try_from(date.day()).ok()?,
    })
}

/// `table` for the test `orientation` (validated again).
pub fn with_orientation(
    mut table: CalibrationTable,
    orientation: Orientation,
) -> Result<CalibrationTable, BuildError> {
    table.orientation = orientation;
    table.validate().map_err(BuildError::Table)?;
    Ok(table)
}

/// Today's UTC date from the system clock.
pub fn today_utc() -> CalibrationDate {
    let today = jiff::Timestamp::now()
        .to_zoned_datetime(jiff::tz::TimeZone::UTC)
        .date();
    calibration_date(today).unwrap_or(CalibrationDate {
        year: 1970,
        month: 1,
        day: 1,
    })
}

#[cfg(test)]
mod orientation_tests {
    use super::*;

    #[test]
    fn named_orientations_and_components_parse_and_nonsense_is_refused() {
        let o = parse_orientation("0g").unwrap();
        assert_eq!(
            (o.nominal_input.0, o.cross.a_p.0, o.cross.a_o.0),
            (0.0, 1.0, 0.0)
        );
        let o = parse_orientation("1g").unwrap();
        assert_eq!(
            (o.nominal_input.0, o.cross.a_p.0, o.cross.a_o.0),
            (1.0, 0.0, 0.0)
        );
        let o = parse_orientation("0.5, 0.866, 0").unwrap();
        assert_eq!(
            (o.nominal_input.0, o.cross.a_p.0, o.cross.a_o.0),
            (0.5, 0.866, 0.0)
        );
        // Written into the table and read back from its encoding.
        let t = with_orientation(
            accomp::reference::paper_order2_table(),
            parse_orientation("0g").unwrap(),
        )
        .unwrap();
        let back = CalibrationTable::decode(&t.encode()).unwrap();
        assert_eq!(back.orientation, parse_orientation("0g").unwrap());
        for bad in ["2g", "1,2", "1,nan,0", ""] {
            assert!(matches!(
                parse_orientation(bad),
                Err(BuildError::Orientation(_))
            ));
        }
    }
}
