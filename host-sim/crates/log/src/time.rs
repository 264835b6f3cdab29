//! UTC instants as seconds since the Unix epoch, parsed from and printed as ISO 8601
//! (`YYYY-MM-DDTHH:MM:SS[.fff]Z`): the one place the host reads and writes a time stamp (the
//! simulator's `start_utc`, the discovery's record formats). Leap seconds are ignored (POSIX time), which is far below what
//! a daily tide or thermal cycle can notice. A civil time becomes seconds through the core's
//! calendar ([`UtcTime::new`] decides which days exist, [`UtcTime::posix_seconds`] counts them),
//! the same conversion the tide model uses; printing takes the civil date of a day count from
//! jiff. The seconds are f64 because the simulator and the analyses count time in f64 seconds.

use std::fmt;

use jiff::civil::Date;
use jiff::tz::TimeZone;
use jiff::Timestamp;

use accomp::tide::UtcTime;

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

/// The fields of `YYYY-MM-DD[T ]HH:MM[:SS[.fraction]][Z]`, unchecked.
struct Fields {
    date: (i64, i64, i64),
    hour_minute: (i64, i64),
    /// `None` when the text stops at the minutes.
    second: Option<f64>,
    /// Whether the text ends in `Z`.
    zulu: bool,
}

fn fields(text: &str) -> Option<Fields> {
    let t = text.trim();
    let (t, zulu) = match t.strip_suffix('Z') {
        Some(t) => (t, true),
        None => (t, false),
    };
    let (date, time) = t.split_once(['T', ' '])?;
    let mut dp = date.split('-');
    let num = |p: Option<&str>| p?.parse::<i64>().ok();
    let date = (num(dp.next())?, num(dp.next())?, num(dp.next())?);
    let mut tp = time.split(':');
    let hour_minute = (num(tp.next())?, num(tp.next())?);
    let second = match tp.next() {
        Some(s) => Some(s.parse::<f64>().ok()?),
        None => None,
    };
    if dp.next().is_some() || tp.next().is_some() {
        return None;
    }
    Some(Fields {
        date,
        hour_minute,
        second,
        zulu,
    })
}

/// Parses a record's time stamp, `YYYY-MM-DD[T ]HH:MM[:SS[.fff]][Z]`, to Unix seconds (the
/// lenient reading of [`Utc::parse`]: `Z` and seconds may be left out; see
/// [`Fields::unix_seconds`] for the range).
pub fn parse_utc(text: &str) -> Option<f64> {
    let f = fields(text)?;
    f.unix_seconds(f.second.unwrap_or(0.0))
}

impl Fields {
    /// Unix seconds of these fields with `second`, by the core's calendar ([`UtcTime::new`],
    /// [`UtcTime::posix_seconds`]: whole seconds in exact integer arithmetic, the fraction added
    /// after). `None` for a day or time that does not exist, or outside what the tide model
    /// takes (years 1600–2400; a leap second's 60.x s is accepted there and counted
    /// POSIX-style, as the next minute's first second).
    fn unix_seconds(&self, second: f64) -> Option<f64> {
        let small = |v: i64| u8::try_from(v).ok();
        let t = UtcTime::new(
            i32::try_from(self.date.0).ok()?,
            small(self.date.1)?,
            small(self.date.2)?,
            small(self.hour_minute.0)?,
            small(self.hour_minute.1)?,
            second,
        )
        .ok()?;
        Some(t.posix_seconds())
    }
}

/// Formats Unix seconds as `YYYY-MM-DDTHH:MM:SS.sssZ` (always milliseconds; the date from
/// jiff, proleptic Gregorian). [`Utc`]'s `Display` leaves out a zero fraction.
pub fn format_utc(unix_s: f64) -> String {
    let u = Utc(unix_s);
    match u.civil_ms() {
        Some(c) => format!("{}.{:03}Z", c.to_seconds(), c.ms),
        None => u.to_string(),
    }
}

/// An instant to the millisecond on the civil UTC calendar.
struct CivilMs {
    date: Date,
    hms: (i64, i64, i64),
    ms: i64,
}

impl CivilMs {
    /// `YYYY-MM-DDTHH:MM:SS` (no fraction, no zone).
    fn to_seconds(&self) -> String {
        let (y, m, d) = (self.date.year(), self.date.month(), self.date.day());
        let (h, mi, s) = self.hms;
        format!("{y:04}-{m:02}-{d:02}T{h:02}:{mi:02}:{s:02}")
    }
}

impl Utc {
    /// Parses `YYYY-MM-DDTHH:MM:SS[.fraction]Z` (a space may replace the `T`; years
    /// 1600–2400, [`Fields::unix_seconds`]).
    pub fn parse(s: &str) -> Result<Utc, UtcParseError> {
        let err = || UtcParseError(s.to_string());
        let f = fields(s).ok_or_else(err)?;
        let sec = f.second.ok_or_else(err)?;
        if !f.zulu || !(0.0..60.0).contains(&sec) {
            return Err(err());
        }
        f.unix_seconds(sec).map(Utc).ok_or_else(err)
    }

    /// The civil date and time, rounded to the millisecond (`None` beyond jiff's years).
    fn civil_ms(self) -> Option<CivilMs> {
        let ms = (self.0 * 1000.0).round() as i64;
        let days = ms.div_euclid(86_400_000);
        let rem = ms.rem_euclid(86_400_000);
        Some(CivilMs {
            date: utc_date(days * 86_400)?,
            hms: (rem / 3_600_000, rem / 60_000 % 60, rem / 1000 % 60),
            ms: rem % 1000,
        })
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
        let Some(c) = self.civil_ms() else {
            // Beyond jiff's years (never met by a real log): the seconds themselves.
            return write!(
                f,
                "{} s since 1970-01-01T00:00:00Z (outside the calendar's years −9999..=9999)",
                self.0
            );
        };
        write!(f, "{}", c.to_seconds())?;
        if c.ms != 0 {
            write!(f, ".{:03}", c.ms)?;
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

    /// The simulator's strict reading and the discovery's lenient one were two parsers; they
    /// now share the fields and agree wherever both accept a text.
    #[test]
    fn strict_and_lenient_readings_agree() {
        for s in [
            "2000-01-01T12:00:00Z",
            "2024-02-29 23:59:30.5Z",
            "2021-06-08T00:00:00.000Z",
            "2020-07-31T12:15:00.015Z",
        ] {
            assert_eq!(parse_utc(s), Some(Utc::parse(s).unwrap().0), "{s}");
            assert_eq!(
                Utc::parse(&format_utc(Utc::parse(s).unwrap().0)),
                Utc::parse(s)
            );
        }
        // The lenient reading also takes what a record's header may hold.
        assert_eq!(parse_utc("2021-06-08 00:00"), Some(1_623_110_400.0));
        assert_eq!(parse_utc("2021-06-08T00:00:00"), Some(1_623_110_400.0));
        assert_eq!(format_utc(1_623_110_400.0), "2021-06-08T00:00:00.000Z");
        // Rounding to the millisecond carries into the minute (was "00:00:60.000").
        assert_eq!(format_utc(1_623_110_459.999_6), "2021-06-08T00:01:00.000Z");
        assert_eq!(parse_utc("2021-06-08-01T00:00:00Z"), None);
    }

    /// Civil time to seconds was jiff's calendar here and the core's Julian day count in the
    /// tide model; it is now the core's alone. Checked against jiff (an independent calendar)
    /// over the years the core takes: every 1st and last day of a month at an odd time of day,
    /// and 29 February of leap and century years.
    #[test]
    fn the_cores_conversion_agrees_with_jiffs_calendar_over_its_years() {
        use jiff::civil::DateTime;
        let jiff_seconds = |y: i16, mo: i8, d: i8, h: i8, mi: i8, s: i8| {
            DateTime::new(y, mo, d, h, mi, s, 0)
                .unwrap()
                .to_zoned_datetime(TimeZone::UTC)
                .unwrap()
                .timestamp()
                .as_second() as f64
        };
        let mut checked = 0;
        for y in (1600..=2400).step_by(7).chain([1900, 2000, 2100, 2400]) {
            for mo in 1..=12u8 {
                let last = Date::new(y as i16, mo as i8, 1).unwrap().days_in_month() as u8;
                for d in [1, last] {
                    let core = UtcTime::new(y, mo, d, 13, 47, 29.25)
                        .unwrap()
                        .posix_seconds();
                    let old = jiff_seconds(y as i16, mo as i8, d as i8, 13, 47, 29) + 0.25;
                    assert_eq!(core, old, "{y}-{mo}-{d}");
                    checked += 1;
                }
            }
        }
        assert!(checked > 2_000);
        for (y, leap) in [(2024, true), (2000, true), (1900, false), (2100, false)] {
            assert_eq!(UtcTime::new(y, 2, 29, 0, 0, 0.0).is_ok(), leap, "{y}");
        }
        // Outside the core's years: refused by both readings.
        assert_eq!(parse_utc("1599-12-31T00:00:00Z"), None);
        assert!(Utc::parse("2401-01-01T00:00:00Z").is_err());
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
