//! Checks that both manifest kinds share: names that become file names,
//! positive numbers, channels and their units, the fit band and specimens
//! (into the simulator's [`SpecimenModel`]); the identification section has
//! its own file (`identification.rs`). Each
//! check reports through `bad(key path, message)` and never stops at the
//! first problem.

use super::keypath::KeyPath;
use super::raw::{Channel, Channels, Role, Specimen, SpecimenKind};
use crate::ingest::Column;
use crate::model::{BoucWen, Duffing, Friction, SpecimenModel};
use crate::units::UnitKind;

/// The longest name that becomes part of a file name (a run id, a
/// campaign's name), in bytes: a run's files are named after it
/// (`figures/frf-<id>.svg`, `tables/model-<id>.parquet`, its page), and
/// file systems refuse names over 255 bytes; this leaves room for the
/// longest prefix and suffix.
pub const MAX_SLUG_BYTES: usize = 200;

pub(super) fn check_slug(s: &str, path: &KeyPath, bad: &mut impl FnMut(KeyPath, String)) {
    if s.is_empty() {
        bad(path.clone(), "must not be empty".into());
    } else if s.len() > MAX_SLUG_BYTES {
        bad(
            path.clone(),
            format!(
                "is {} bytes long; at most {MAX_SLUG_BYTES} (it names files and folders, and file systems refuse names over 255 bytes)",
                s.len()
            ),
        );
    } else if !s
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'))
        || s.starts_with('.')
    {
        bad(
            path.clone(),
            format!(
                "`{s}` may hold only ASCII letters (a-z, A-Z), digits, `.`, `_` and `-`, and may not start with `.` (it names files and folders)"
            ),
        );
    }
}

/// A text that is not the ISO 8601 date a manifest or run table asks for.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("must be an ISO 8601 date, YYYY-MM-DD or YYYY-MM-DDTHH:MM:SS[Z] (got {text:?}: {why})")]
pub struct BadDate {
    pub text: String,
    pub why: DateFault,
}

/// What is wrong with a date.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DateFault {
    #[error("the date is not YYYY-MM-DD")]
    NotYmd,
    #[error("there is no month {0:02}")]
    Month(u32),
    #[error("{year:04}-{month:02} has days 01 to {days}")]
    Day { year: u32, month: u32, days: u32 },
    #[error("the time is not HH:MM:SS, optionally followed by Z")]
    NotHms,
    #[error("there is no time {0}")]
    Time(String),
}

/// A date as ISO 8601 `YYYY-MM-DD`, or `YYYY-MM-DDTHH:MM:SS` optionally
/// ending in `Z`, checked against the calendar. Returns the normalised text
/// (no surrounding space, upper-case `T` and `Z`; a space or `t` between date
/// and time, as RFC 3339 allows, becomes `T`) or, when it is not such a
/// date, the message saying so.
pub fn normalise_date(text: &str) -> Result<String, BadDate> {
    let s = text.trim();
    let fail = |why: DateFault| {
        Err(BadDate {
            text: text.to_string(),
            why,
        })
    };
    let (date, time) = match s.find(['T', 't', ' ']) {
        Some(i) => (&s[..i], Some(&s[i + 1..])),
        None => (s, None),
    };
    let Some([y, m, d]) = digit_fields(date, '-', [4, 2, 2]) else {
        return fail(DateFault::NotYmd);
    };
    if !(1..=12).contains(&m) {
        return fail(DateFault::Month(m));
    }
    let leap = y % 4 == 0 && (y % 100 != 0 || y % 400 == 0);
    let days = match m {
        2 if leap => 29,
        2 => 28,
        4 | 6 | 9 | 11 => 30,
        _ => 31,
    };
    if !(1..=days).contains(&d) {
        return fail(DateFault::Day {
            year: y,
            month: m,
            days,
        });
    }
    let Some(time) = time else {
        return Ok(date.to_string());
    };
    let (clock, zulu) = match time.strip_suffix(['Z', 'z']) {
        Some(c) => (c, "Z"),
        None => (time, ""),
    };
    let Some([h, min, sec]) = digit_fields(clock, ':', [2, 2, 2]) else {
        return fail(DateFault::NotHms);
    };
    if h > 23 || min > 59 || sec > 59 {
        return fail(DateFault::Time(clock.to_string()));
    }
    Ok(format!("{date}T{clock}{zulu}"))
}

/// The numbers of `text` split at `sep`, each field all ASCII digits of the
/// given width; None when it is not so.
fn digit_fields<const N: usize>(text: &str, sep: char, widths: [usize; N]) -> Option<[u32; N]> {
    let fields: Vec<&str> = text.split(sep).collect();
    if fields.len() != N {
        return None;
    }
    let mut out = [0; N];
    for ((f, w), o) in fields.iter().zip(widths).zip(&mut out) {
        if f.len() != w || !f.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        *o = f.parse().ok()?;
    }
    Some(out)
}

/// A run's `date`, normalised (see [`normalise_date`]); None, with the
/// problem reported, when it is not an ISO 8601 date.
pub(super) fn check_date(
    text: &str,
    path: &KeyPath,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<String> {
    normalise_date(text)
        .map_err(|e| bad(path.clone(), e.to_string()))
        .ok()
}

/// The range of a physical quantity a servo-hydraulic test can have
///: wide enough for any lab (a milligram to a 10,000 t mass, a
/// spring from a rubber band's to a steel block's 1e10 N/m with margin, a P
/// gain from 1e-6 to 1e6), narrow enough that the model's products (Eqs.
/// 12-17, with a1b0 ~ 1e9-1e12) stay far inside f64. Beyond it a number is
/// a typo or a unit slip, refused at check time rather than by the night.
#[derive(Debug, Clone, Copy)]
pub struct PhysicalRange {
    pub lo: f64,
    pub hi: f64,
    pub unit: &'static str,
}

pub const MASS_RANGE: PhysicalRange = PhysicalRange {
    lo: 1e-6,
    hi: 1e7,
    unit: "kg",
};
pub const STIFFNESS_RANGE: PhysicalRange = PhysicalRange {
    lo: 1e-3,
    hi: 1e13,
    unit: "N/m",
};
pub const DAMPING_RANGE: PhysicalRange = PhysicalRange {
    lo: 0.0,
    hi: 1e12,
    unit: "N s/m",
};
pub const P_GAIN_RANGE: PhysicalRange = PhysicalRange {
    lo: 1e-6,
    hi: 1e6,
    unit: "",
};

/// Whether a finite `v` lies in `range`; a finite value outside it is
/// named (a non-finite one is the finiteness checks' to name).
pub(super) fn plausible(
    v: f64,
    range: PhysicalRange,
    path: &KeyPath,
    bad: &mut impl FnMut(KeyPath, String),
) -> bool {
    if !v.is_finite() || (range.lo..=range.hi).contains(&v) {
        return true;
    }
    let unit = if range.unit.is_empty() {
        String::new()
    } else {
        format!(" {}", range.unit)
    };
    let lo = if range.lo == 0.0 {
        "0".to_string()
    } else {
        format!("{:e}", range.lo)
    };
    bad(
        path.clone(),
        format!(
            "{v:e} is beyond what a servo-hydraulic test can have ({lo} to {:e}{unit}): a typo or a unit slip?",
            range.hi
        ),
    );
    false
}

/// The flow-pressure law's nameplate under `rig` (`supply_pressure_pa`
/// and `piston_area_m2`): both or neither, each positive.
pub(super) fn check_nameplate(
    supply_pressure_pa: Option<f64>,
    piston_area_m2: Option<f64>,
    rig: &KeyPath,
    bad: &mut impl FnMut(KeyPath, String),
) {
    match (supply_pressure_pa, piston_area_m2) {
        (Some(ps), Some(a)) => {
            positive(ps, &rig.key("supply_pressure_pa"), bad);
            positive(a, &rig.key("piston_area_m2"), bad);
        }
        (Some(_), None) => bad(
            rig.key("piston_area_m2"),
            "the flow-pressure law needs the piston area beside `supply_pressure_pa` (F_max = A P_s)".into(),
        ),
        (None, Some(_)) => bad(
            rig.key("supply_pressure_pa"),
            "the flow-pressure law needs the supply pressure beside `piston_area_m2` (F_max = A P_s)".into(),
        ),
        (None, None) => {}
    }
}

pub(super) fn positive(v: f64, path: &KeyPath, bad: &mut impl FnMut(KeyPath, String)) -> bool {
    if v.is_finite() && v > 0.0 {
        true
    } else {
        bad(path.clone(), format!("must be positive (got {v})"));
        false
    }
}

fn check_channel(
    ch: &Channel,
    kind: UnitKind,
    path: &KeyPath,
    bad: &mut impl FnMut(KeyPath, String),
) {
    if ch.unit.kind() != kind {
        let need = match kind {
            UnitKind::Length => "m, cm, mm or in",
            UnitKind::Force => "N, kN or lbf",
        };
        bad(
            path.key("unit"),
            format!(
                "`{}` does not fit this channel; use {need}",
                ch.unit.symbol()
            ),
        );
    }
    if !(ch.scale.is_finite() && ch.scale != 0.0) {
        bad(
            path.key("scale"),
            format!("must be finite and non-zero (got {})", ch.scale),
        );
    }
    if !ch.offset.is_finite() {
        bad(path.key("offset"), "must be finite".into());
    }
    if let Some([lo, hi]) = ch.range
        && !(lo.is_finite() && hi.is_finite() && lo < hi)
    {
        bad(
            path.key("range"),
            format!("must be [min, max] with finite min < max (got [{lo}, {hi}])"),
        );
    }
    if let Column::Name(n) = &ch.column
        && n.is_empty()
    {
        bad(path.key("column"), "must not be empty".into());
    }
}

pub(super) fn check_channels(ch: &Channels, path: &KeyPath, bad: &mut impl FnMut(KeyPath, String)) {
    if let Some(t) = &ch.time {
        let p = path.key("time");
        match (&t.column, t.sample_rate_hz) {
            (Some(_), Some(_)) => bad(
                p.clone(),
                "give either `column` or `sample_rate_hz`, not both".into(),
            ),
            (None, Some(hz)) => {
                positive(hz, &p.key("sample_rate_hz"), bad);
            }
            (None, None) => bad(p.clone(), "give `column` or `sample_rate_hz`".into()),
            (Some(_), None) => {}
        }
        if t.unit.is_some() && t.column.is_none() {
            bad(p.key("unit"), "applies only to a time `column`".into());
        }
    }
    if let Some(c) = &ch.command {
        check_channel(c, UnitKind::Length, &path.key("command"), bad);
    }
    if let Some(c) = &ch.displacement {
        check_channel(c, UnitKind::Length, &path.key("displacement"), bad);
    }
    if let Some(c) = &ch.force {
        check_channel(c, UnitKind::Force, &path.key("force"), bad);
    }
}

pub(super) fn check_band(band: [f64; 2], path: &KeyPath, bad: &mut impl FnMut(KeyPath, String)) {
    let [lo, hi] = band;
    if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && hi > lo) {
        bad(
            path.clone(),
            format!("must be [low, high] with 0 <= low < high (got [{lo}, {hi}])"),
        );
    }
}

/// The specimen a run of `role` needs, from the keys given: each value in
/// its range, each model's keys only with it, and the keys the role takes.
pub(super) fn check_specimen(
    role: Role,
    spec: Option<&Specimen>,
    path: &KeyPath,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<SpecimenModel> {
    let s = spec.cloned().unwrap_or_default();
    let mut ok = check_linear_values(&s, path, bad);
    ok &= check_model_keys(&s, path, bad);
    if s.model != SpecimenKind::Linear && matches!(role, Role::NoSpecimen | Role::Spring) {
        bad(
            path.key("model"),
            format!(
                "a {} run identifies the rig with a linear specimen (Eqs. 18-19); nonlinear specimens are for validation and fit runs",
                role.as_str()
            ),
        );
        return None;
    }
    match role {
        Role::NoSpecimen => no_specimen(&s, path, bad),
        Role::Spring => spring_specimen(&s, ok, path, bad),
        Role::Validation | Role::Fit if s.model == SpecimenKind::Linear => {
            linear_specimen(&s, path, bad).filter(|_| ok)
        }
        Role::Validation | Role::Fit => nonlinear_specimen(&s, ok, path, bad),
    }
}

/// The mass, stiffness and damping, where given, in their plausible
/// ranges (the mass and stiffness positive, the damping not negative).
fn check_linear_values(
    s: &Specimen,
    path: &KeyPath,
    bad: &mut impl FnMut(KeyPath, String),
) -> bool {
    let mut ok = true;
    for (k, v, range) in [
        ("mass_kg", s.mass_kg, MASS_RANGE),
        ("stiffness_n_per_m", s.stiffness_n_per_m, STIFFNESS_RANGE),
    ] {
        if let Some(v) = v {
            ok &= positive(v, &path.key(k), bad) && plausible(v, range, &path.key(k), bad);
        }
    }
    if let Some(c) = s.damping_ns_per_m {
        if !(c.is_finite() && c >= 0.0) {
            bad(
                path.key("damping_ns_per_m"),
                format!("must be zero or positive (got {c})"),
            );
            ok = false;
        } else {
            ok &= plausible(c, DAMPING_RANGE, &path.key("damping_ns_per_m"), bad);
        }
    }
    ok
}

/// Keys that belong to one nonlinear model only, given only with it.
fn check_model_keys(s: &Specimen, path: &KeyPath, bad: &mut impl FnMut(KeyPath, String)) -> bool {
    let model_keys: [(&str, bool, SpecimenKind); 4] = [
        (
            "cubic_stiffness_n_per_m3",
            s.cubic_stiffness_n_per_m3.is_some(),
            SpecimenKind::Duffing,
        ),
        (
            "coulomb_force_n",
            s.coulomb_force_n.is_some(),
            SpecimenKind::Friction,
        ),
        (
            "smoothing_velocity_m_per_s",
            s.smoothing_velocity_m_per_s.is_some(),
            SpecimenKind::Friction,
        ),
        ("bouc_wen", s.bouc_wen.is_some(), SpecimenKind::BoucWen),
    ];
    let mut ok = true;
    for (key, given, owner) in model_keys {
        if given && s.model != owner {
            let name = serde_json::to_value(owner)
                .ok()
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap_or_default();
            bad(path.key(key), format!("applies only to model = \"{name}\""));
            ok = false;
        }
    }
    ok
}

/// A no-specimen run's specimen: none, so no mass, damping or stiffness.
fn no_specimen(
    s: &Specimen,
    path: &KeyPath,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<SpecimenModel> {
    let given: Vec<&str> = [
        ("mass_kg", s.mass_kg.is_some()),
        ("damping_ns_per_m", s.damping_ns_per_m.is_some()),
        ("stiffness_n_per_m", s.stiffness_n_per_m.is_some()),
    ]
    .iter()
    .filter(|(_, g)| *g)
    .map(|(k, _)| *k)
    .collect();
    if !given.is_empty() {
        bad(
            path.clone(),
            format!(
                "a no_specimen run has no specimen; remove {}",
                given.join(", ")
            ),
        );
        return None;
    }
    Some(SpecimenModel::None)
}

/// A spring run's specimen: its stiffness alone; `ok` is whether the
/// values passed their checks.
fn spring_specimen(
    s: &Specimen,
    ok: bool,
    path: &KeyPath,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<SpecimenModel> {
    let Some(k) = s.stiffness_n_per_m else {
        bad(
            path.key("stiffness_n_per_m"),
            "a spring run needs the spring's stiffness".into(),
        );
        return None;
    };
    if s.mass_kg.is_some() || s.damping_ns_per_m.is_some() {
        bad(
            path.clone(),
            "a spring run is massless and undamped in the paper's model (Sec. 3.1); give only stiffness_n_per_m, or use role `validation` for a specimen with mass".into(),
        );
        return None;
    }
    ok.then_some(SpecimenModel::Spring {
        stiffness_n_per_m: k,
    })
}

/// A linear specimen of a validation or fit run, by the keys given: none, a
/// spring, or an SDOF (Eq. 15).
fn linear_specimen(
    s: &Specimen,
    path: &KeyPath,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<SpecimenModel> {
    use SpecimenModel as M;
    let lin = match (s.mass_kg, s.damping_ns_per_m, s.stiffness_n_per_m) {
        (None, None, None) => M::None,
        (None, None, Some(k)) => M::Spring {
            stiffness_n_per_m: k,
        },
        (Some(m), c, Some(k)) => M::LinearSdof {
            mass_kg: m,
            damping_ns_per_m: c.unwrap_or(0.0),
            stiffness_n_per_m: k,
        },
        (Some(_), _, None) => {
            bad(
                path.key("stiffness_n_per_m"),
                "an SDOF specimen needs its stiffness".into(),
            );
            return None;
        }
        (None, Some(_), _) => {
            bad(
                path.key("mass_kg"),
                "a damped specimen needs its mass (the paper's massless model has no damping)"
                    .into(),
            );
            return None;
        }
    };
    Some(lin)
}

/// A nonlinear specimen of a validation or fit run: every parameter of its
/// model is required, and its signs and ranges are the simulator's own
/// checks (they name the parameter). `ok` says whether the common checks
/// passed.
fn nonlinear_specimen(
    s: &Specimen,
    mut ok: bool,
    path: &KeyPath,
    bad: &mut impl FnMut(KeyPath, String),
) -> Option<SpecimenModel> {
    use SpecimenModel as M;
    let mut need = |key: &str, v: Option<f64>| -> f64 {
        v.unwrap_or_else(|| {
            bad(
                path.key(key),
                format!("a {} specimen needs `{key}`", model_name(s.model)),
            );
            ok = false;
            f64::NAN
        })
    };
    let m = need("mass_kg", s.mass_kg);
    let k = need("stiffness_n_per_m", s.stiffness_n_per_m);
    let c = s.damping_ns_per_m.unwrap_or(0.0);
    let model = match s.model {
        SpecimenKind::Duffing => M::Duffing(Duffing {
            mass_kg: m,
            damping_ns_per_m: c,
            stiffness_n_per_m: k,
            cubic_stiffness_n_per_m3: need("cubic_stiffness_n_per_m3", s.cubic_stiffness_n_per_m3),
        }),
        SpecimenKind::Friction => M::Friction(Friction {
            mass_kg: m,
            damping_ns_per_m: c,
            stiffness_n_per_m: k,
            coulomb_force_n: need("coulomb_force_n", s.coulomb_force_n),
            smoothing_velocity_m_per_s: need(
                "smoothing_velocity_m_per_s",
                s.smoothing_velocity_m_per_s,
            ),
        }),
        SpecimenKind::BoucWen => match &s.bouc_wen {
            Some(bw) => M::BoucWen(BoucWen {
                mass_kg: m,
                damping_ns_per_m: c,
                stiffness_n_per_m: k,
                alpha: bw.alpha,
                a: bw.a,
                beta_per_m_pow_n: bw.beta_per_m_pow_n,
                gamma_per_m_pow_n: bw.gamma_per_m_pow_n,
                n: bw.n,
            }),
            None => {
                bad(
                    path.key("bouc_wen"),
                    "a bouc_wen specimen needs its `bouc_wen` table (alpha, a, beta_per_m_pow_n, gamma_per_m_pow_n, n)".into(),
                );
                return None;
            }
        },
        SpecimenKind::Linear => unreachable!("handled above"),
    };
    if !ok {
        return None;
    }
    // Signs and ranges, by the simulator's own checks (they name the parameter).
    match model.validate() {
        Ok(()) => Some(model),
        Err(e) => {
            bad(path.clone(), e.to_string());
            None
        }
    }
}

fn model_name(k: SpecimenKind) -> &'static str {
    match k {
        SpecimenKind::Linear => "linear",
        SpecimenKind::Duffing => "duffing",
        SpecimenKind::BoucWen => "bouc_wen",
        SpecimenKind::Friction => "friction",
    }
}

#[cfg(test)]
mod tests {
    use super::normalise_date;

    #[test]
    fn dates_are_iso_8601_and_come_back_normalised() {
        for (given, normal) in [
            ("2024-05-01", "2024-05-01"),
            (" 2024-02-29 ", "2024-02-29"),
            ("2000-02-29T23:59:59", "2000-02-29T23:59:59"),
            ("2024-05-01t07:30:00z", "2024-05-01T07:30:00Z"),
            ("2024-05-01 07:30:00Z", "2024-05-01T07:30:00Z"),
        ] {
            assert_eq!(normalise_date(given).as_deref(), Ok(normal), "{given:?}");
        }
        for (given, why) in [
            ("2023-02-29", "2023-02 has days 01 to 28"),
            ("1900-02-29", "1900-02 has days 01 to 28"),
            ("2024-04-31", "2024-04 has days 01 to 30"),
            ("2024-13-01", "there is no month 13"),
            ("2024-00-10", "there is no month 00"),
            ("24-05-01", "the date is not YYYY-MM-DD"),
            ("2024-5-1", "the date is not YYYY-MM-DD"),
            ("01/05/2024", "the date is not YYYY-MM-DD"),
            ("2024-05-01T24:00:00", "there is no time 24:00:00"),
            (
                "2024-05-01T10:00",
                "the time is not HH:MM:SS, optionally followed by Z",
            ),
            (
                "2024-05-01T10:00:00+02:00",
                "the time is not HH:MM:SS, optionally followed by Z",
            ),
            ("", "the date is not YYYY-MM-DD"),
        ] {
            assert_eq!(
                normalise_date(given).map_err(|e| e.to_string()),
                Err(format!(
                    "must be an ISO 8601 date, YYYY-MM-DD or YYYY-MM-DDTHH:MM:SS[Z] (got {given:?}: {why})"
                )),
                "{given:?}"
            );
        }
    }
}
