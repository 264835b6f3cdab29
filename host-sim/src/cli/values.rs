//! The command line's names for the domain's value enums (`plot::Format`, `plot::Kind`,
//! `discover::import::Format`): the analysis crate holds no clap, so each enum is wrapped here and
//! given its `--help` name and text.

use clap::builder::PossibleValue;

/// A newtype over a domain enum that clap parses, with each variant's name and help text.
macro_rules! value_enum {
    ($(#[$meta:meta])* $wrapper:ident($inner:ty) { $($variant:path => $name:literal: $help:literal,)+ }) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        pub struct $wrapper(pub $inner);

        impl clap::ValueEnum for $wrapper {
            fn value_variants<'a>() -> &'a [Self] {
                &[$($wrapper($variant)),+]
            }
            fn to_possible_value(&self) -> Option<PossibleValue> {
                Some(match self.0 {
                    $($variant => PossibleValue::new($name).help($help),)+
                })
            }
        }
    };
}

value_enum! {
    /// `--format` / `--report-format`: an image format.
    ImageFormat(crate::plot::Format) {
        crate::plot::Format::Png => "png": "Raster, text drawn with the embedded DejaVu Sans",
        crate::plot::Format::Svg => "svg": "Vector, text left to the viewer's sans-serif font",
    }
}

value_enum! {
    /// `accomp plot --kind`: which figure(s).
    PlotKind(crate::plot::Kind) {
        crate::plot::Kind::All => "all": "Every figure the log has columns for",
        crate::plot::Kind::Temperature => "temperature": "Fig. 2: instrument temperature",
        crate::plot::Kind::Output => "output": "Fig. 3: 1 g output before/after compensation",
        crate::plot::Kind::Tilt => "tilt": "Fig. 4: foundation tilt",
        crate::plot::Kind::ZeroG => "zero-g": "Fig. 5: 0 g output before/after tilt compensation",
        crate::plot::Kind::Adev => "adev": "Overlapping Allan deviation with confidence bands",
    }
}

value_enum! {
    /// `accomp discover --format`: the record's format.
    RecordFormat(crate::discover::import::Format) {
        crate::discover::import::Format::Auto => "auto": "Guess from the extension and the header",
        crate::discover::import::Format::Log => "log": "Our stability-test log (docs/log-format.md)",
        crate::discover::import::Format::GmetrologyTsf => "gmetrology-tsf": "gMetrology relative gravimeter, whitespace columns, Beijing time",
        crate::discover::import::Format::AqgCsv => "aqg-csv": "AQG quantum gravimeter CSV converted from MiniSEED (time_s from 2020-07-31T12:15:00.015Z)",
    }
}
