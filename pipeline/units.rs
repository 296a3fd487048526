//! Physical units of logged channels and their factors to SI. Units are
//! explicit in the manifest and in the simulator's sensors; every conversion
//! to SI happens once, at ingest (and back, once, where the simulator writes
//! a log in a channel's unit).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Physical units a channel may be given in; converted to SI once, at ingest.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
pub enum Unit {
    #[serde(rename = "m")]
    Meter,
    #[serde(rename = "cm")]
    Centimeter,
    #[serde(rename = "mm")]
    Millimeter,
    #[serde(rename = "in")]
    Inch,
    #[serde(rename = "N")]
    Newton,
    #[serde(rename = "kN")]
    Kilonewton,
    #[serde(rename = "lbf")]
    PoundForce,
}

/// What a unit measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UnitKind {
    Length,
    Force,
}

impl Unit {
    /// Factor to the SI unit (m or N).
    pub fn to_si(self) -> f64 {
        match self {
            Unit::Meter => 1.0,
            Unit::Centimeter => 1e-2,
            Unit::Millimeter => 1e-3,
            Unit::Inch => 0.0254,
            Unit::Newton => 1.0,
            Unit::Kilonewton => 1e3,
            // 1 lbf = 0.45359237 kg * 9.80665 m/s^2 (exact by definition).
            Unit::PoundForce => 4.448_221_615_260_5,
        }
    }

    pub fn kind(self) -> UnitKind {
        match self {
            Unit::Meter | Unit::Centimeter | Unit::Millimeter | Unit::Inch => UnitKind::Length,
            Unit::Newton | Unit::Kilonewton | Unit::PoundForce => UnitKind::Force,
        }
    }

    pub fn symbol(self) -> &'static str {
        match self {
            Unit::Meter => "m",
            Unit::Centimeter => "cm",
            Unit::Millimeter => "mm",
            Unit::Inch => "in",
            Unit::Newton => "N",
            Unit::Kilonewton => "kN",
            Unit::PoundForce => "lbf",
        }
    }
}

/// Unit of a time column.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
pub enum TimeUnit {
    #[serde(rename = "s")]
    Second,
    #[serde(rename = "ms")]
    Millisecond,
}

impl TimeUnit {
    pub fn to_si(self) -> f64 {
        match self {
            TimeUnit::Second => 1.0,
            TimeUnit::Millisecond => 1e-3,
        }
    }
}

/// A number with `sig` significant digits: plain between 1e-3 and 1e6,
/// scientific outside; a dash for none.
pub fn format_number(x: f64, sig: usize) -> String {
    let sig = sig.max(1);
    if x == 0.0 {
        return "0".into();
    }
    let e = x.abs().log10().floor() as i32;
    if (-3..6).contains(&e) {
        let decimals = (sig as i32 - 1 - e).max(0) as usize;
        let s = format!("{x:.decimals$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        format!("{:.*e}", sig - 1, x)
    }
}
