//! Time: UTC calendar instants, Julian dates, sidereal time.

use super::*;

// ---------------------------------------------------------------------------------------------
// Time
// ---------------------------------------------------------------------------------------------

/// A UTC calendar instant (Gregorian calendar), without a parser: fill the fields.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UtcTime {
    /// Year, e.g. 2024.
    pub year: i32,
    /// Month 1..=12.
    pub month: u8,
    /// Day of month 1..=31.
    pub day: u8,
    /// Hour 0..=23.
    pub hour: u8,
    /// Minute 0..=59.
    pub minute: u8,
    /// Seconds, 0 ≤ s < 61.
    pub second: f64,
}

pub(super) fn is_leap_year(year: i32) -> bool {
    (year % 4 == 0 && year % 100 != 0) || year % 400 == 0
}

pub(super) fn days_in_month(year: i32, month: u8) -> u8 {
    match month {
        1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
        4 | 6 | 9 | 11 => 30,
        2 if is_leap_year(year) => 29,
        2 => 28,
        _ => 0,
    }
}

impl UtcTime {
    /// A checked calendar instant.
    pub fn new(
        year: i32,
        month: u8,
        day: u8,
        hour: u8,
        minute: u8,
        second: f64,
    ) -> Result<Self, TideError> {
        if !second.is_finite() {
            return Err(TideError::NotFinite);
        }
        if !(1600..=2400).contains(&year) {
            return Err(TideError::YearOutOfRange);
        }
        if !(1..=12).contains(&month) {
            return Err(TideError::MonthOutOfRange);
        }
        if day == 0 || day > days_in_month(year, month) {
            return Err(TideError::DayOutOfRange);
        }
        if hour > 23 || minute > 59 || !(0.0..61.0).contains(&second) {
            return Err(TideError::TimeOfDayOutOfRange);
        }
        Ok(Self {
            year,
            month,
            day,
            hour,
            minute,
            second,
        })
    }

    /// Julian date (UTC-based) of this instant.
    pub fn julian_date(&self) -> f64 {
        let day_fraction =
            (f64::from(self.hour) * 3600.0 + f64::from(self.minute) * 60.0 + self.second)
                / SECONDS_PER_DAY;
        self.julian_day_number() as f64 - 0.5 + day_fraction
    }

    /// Julian day number of the date (the Julian day that begins at its noon), by the
    /// Fliegel–Van Flandern formula (all quotients are of positive numbers for years after
    /// −4800, so Rust's truncating division is the floor it needs).
    fn julian_day_number(&self) -> i64 {
        let a = (14 - i64::from(self.month)) / 12;
        let y = i64::from(self.year) + 4800 - a;
        let m = i64::from(self.month) + 12 * a - 3;
        i64::from(self.day) + (153 * m + 2) / 5 + 365 * y + y / 4 - y / 100 + y / 400 - 32_045
    }

    /// Seconds since 1970-01-01 00:00 UTC (Unix time, no leap seconds).
    pub fn unix_seconds(&self) -> f64 {
        unix_seconds_from_julian_date(self.julian_date())
    }

    /// Seconds since 1970-01-01 00:00 UTC (POSIX: no leap seconds; a leap second's 60.x s
    /// counts as the next minute's first second), the whole seconds in exact integer
    /// arithmetic and the fraction added after: what a log's `time_s` is computed from.
    /// [`Self::unix_seconds`] goes through the f64 Julian date and loses ~10 µs to its day
    /// count, which would jitter a time stamp.
    pub fn posix_seconds(&self) -> f64 {
        // Julian day number of 1970-01-01.
        const UNIX_EPOCH_JDN: i64 = 2_440_588;
        let whole = (self.julian_day_number() - UNIX_EPOCH_JDN) * 86_400
            + i64::from(self.hour) * 3600
            + i64::from(self.minute) * 60;
        whole as f64 + self.second
    }
}

/// Julian date (UTC-based) of a Unix time in seconds.
#[inline]
pub fn julian_date_from_unix_seconds(unix_s: f64) -> f64 {
    UNIX_EPOCH_JD + unix_s / SECONDS_PER_DAY
}

/// Unix time in seconds of a Julian date (UTC-based).
#[inline]
pub fn unix_seconds_from_julian_date(jd: f64) -> f64 {
    (jd - UNIX_EPOCH_JD) * SECONDS_PER_DAY
}

/// Greenwich mean sidereal time (IAU 1982, Meeus eq. 12.4) in radians, 0..2π.
///
/// UT1 is taken equal to UTC: |UT1 − UTC| < 0.9 s turns the Earth by < 0.004°, a < 0.02 %
/// change of the semidiurnal tide.
pub fn gmst_rad(jd_ut1: f64) -> f64 {
    // Split whole days from the fraction so that 360.98…° × days keeps its precision.
    let d = jd_ut1 - J2000_JD;
    let whole = floor(d);
    let frac = d - whole;
    let t = d / DAYS_PER_CENTURY;
    let deg = 280.460_618_37 + 360.0 * frac + 0.985_647_366_29 * d + 0.000_387_933 * t * t
        - t * t * t / 38_710_000.0;
    let rad = (deg % 360.0) * DEG;
    if rad < 0.0 {
        rad + TWO_PI
    } else {
        rad
    }
}
