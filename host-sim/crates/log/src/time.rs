//! UTC instants as seconds since the Unix epoch, parsed from and printed as ISO 8601
//! (`YYYY-MM-DDTHH:MM:SS[.fff]Z`). Leap seconds are ignored (POSIX time), which is far below what
//! a daily tide or thermal cycle can notice. The calendar (which days exist, day counts) is
//! jiff's; only the f64 seconds are ours, because the simulator and the analyses count time in
//! f64 seconds.

use std::fmt;

use jiff::civil::{Date, DateTime};
use jiff::tz::TimeZone;
use jiff::Timestamp;

/// POSIX seconds of a civil UTC date and time (whole seconds), `None` for a day or time that
/// does not exist or a year outside jiff's −9999..=9999.
pub fn posix_seconds(y: i64, mo: i64, d: i64, h: i64, mi: i64, s: i64) -> Option<i64> {
    let small = |v: i64| i8::try_from(v).ok();
    let dt = DateTime::new(
        i16::try_from(y).ok()?,
        small(mo)?,
        small(d)?,
        small(h)?,
        small(mi)?,
        small(s)?,
        0,
    )
    .ok()?;
    Some(
        dt.to_zoned_datetime(TimeZone::UTC)
            .ok()?
            .timestamp()
            .as_second(),
    )
}

/// The civil UTC date of POSIX second `s` (`None` outside jiff's years −9999..=9999).
pub fn utc_date(s: i64) -> Option<Date> {
    Some(
        Timestamp::from_second(s)
            .ok()?
            .to_zoned_datetime(TimeZone::UTC)
            .date(),
    )
}

/// A UTC instant, seconds since 1970-01-01T00:00:00Z (POSIX, no leap seconds).
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd)]
pub struct Utc(pub f64);

/// Why a UTC string is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("not an ISO 8601 UTC time (YYYY-MM-DDTHH:MM:SSZ): {0:?}")]
pub struct UtcParseError(pub String);

impl Utc {
    /// Parses `YYYY-MM-DDTHH:MM:SS[.fraction]Z` (a space may replace the `T`).
    pub fn parse(s: &str) -> Result<Utc, UtcParseError> {
        let err = || UtcParseError(s.to_string());
        let t = s.trim();
        let t = t.strip_suffix('Z').ok_or_else(err)?;
        let (date, time) = t.split_once(['T', ' ']).ok_or_else(err)?;
        let mut dp = date.split('-');
        let num = |p: Option<&str>| -> Result<i64, UtcParseError> {
            p.ok_or_else(err)?.parse::<i64>().map_err(|_| err())
        };
        let (y, mo, d) = (num(dp.next())?, num(dp.next())?, num(dp.next())?);
        let mut tp = time.split(':');
        let (h, mi) = (num(tp.next())?, num(tp.next())?);
        let sec: f64 = tp.next().ok_or_else(err)?.parse().map_err(|_| err())?;
        if dp.next().is_some() || tp.next().is_some() || !(0.0..60.0).contains(&sec) {
            return Err(err());
        }
        // jiff decides whether the day and the clock time exist.
        let whole = posix_seconds(y, mo, d, h, mi, 0).ok_or_else(err)?;
        Ok(Utc(whole as f64 + sec))
    }

    /// The instant `dt_s` seconds later.
    pub fn plus(self, dt_s: f64) -> Utc {
        Utc(self.0 + dt_s)
    }

    /// Julian date (UT), for ephemerides.
    pub fn julian_date(self) -> f64 {
        self.0 / 86_400.0 + 2_440_587.5
    }
}

impl fmt::Display for Utc {
    /// `YYYY-MM-DDTHH:MM:SSZ`, with milliseconds only when the instant has a fraction.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ms = (self.0 * 1000.0).round() as i64;
        let days = ms.div_euclid(86_400_000);
        let rem = ms.rem_euclid(86_400_000);
        let Some(date) = utc_date(days * 86_400) else {
            // Beyond jiff's years (never met by a real log): the seconds themselves.
            return write!(
                f,
                "{} s since 1970-01-01T00:00:00Z (outside the calendar's years −9999..=9999)",
                self.0
            );
        };
        let (y, m, d) = (date.year(), date.month(), date.day());
        let (h, mi, s, frac) = (
            rem / 3_600_000,
            rem / 60_000 % 60,
            rem / 1000 % 60,
            rem % 1000,
        );
        write!(f, "{y:04}-{m:02}-{d:02}T{h:02}:{mi:02}:{s:02}")?;
        if frac != 0 {
            write!(f, ".{frac:03}")?;
        }
        write!(f, "Z")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_instants_parse_to_their_posix_seconds() {
        // `date -u -d 2000-01-01T12:00:00Z +%s` = 946728000 (J2000.0 in UT).
        assert_eq!(Utc::parse("2000-01-01T12:00:00Z").unwrap().0, 946_728_000.0);
        assert_eq!(Utc::parse("1970-01-01T00:00:00Z").unwrap().0, 0.0);
        // `date -u -d 2024-02-29T23:59:30Z +%s` = 1709251170.
        assert_eq!(
            Utc::parse("2024-02-29 23:59:30.5Z").unwrap().0,
            1_709_251_170.5
        );
        // J2000.0 is JD 2451545.0.
        assert!((Utc(946_728_000.0).julian_date() - 2_451_545.0).abs() < 1e-9);
    }

    #[test]
    fn printing_round_trips() {
        for s in [
            "1990-01-01T01:00:00Z",
            "2017-03-01T08:30:15.250Z",
            "2100-12-31T23:59:59Z",
        ] {
            assert_eq!(Utc::parse(s).unwrap().to_string(), s);
        }
    }

    #[test]
    fn malformed_or_impossible_dates_are_refused() {
        for s in [
            "2017-02-29T00:00:00Z",
            "2017-13-01T00:00:00Z",
            "2017-01-01T24:00:00Z",
            "2017-01-01T00:00:00",
            "yesterday",
        ] {
            assert!(Utc::parse(s).is_err(), "{s}");
        }
    }
}
