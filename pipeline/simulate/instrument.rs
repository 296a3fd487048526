//! The instrument chain between the true signal and the logged number:
//! offset, linear drift, white Gaussian noise, then an A/D converter's
//! quantisation and clipping. Each channel draws from its own reproducible
//! random stream. (Sensor delays are applied exactly inside the plant
//! simulation, not here.)

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::units::Unit;

/// One channel's sensor and conditioning, in the channel's own unit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(rename = "SensorSpec", deny_unknown_fields)]
pub struct Sensor {
    /// The unit the log records this channel in.
    pub unit: Unit,
    /// White noise RMS (in `unit`).
    #[serde(default)]
    pub noise_rms: f64,
    /// Sensor and conditioning delay (s), applied exactly by the plant
    /// simulation.
    #[serde(default)]
    pub delay_s: f64,
    /// Constant offset (in `unit`).
    #[serde(default)]
    pub offset: f64,
    /// Slow linear drift (`unit` per second), zero at t = 0.
    #[serde(default)]
    pub drift_per_s: f64,
    /// ADC quantisation.
    #[serde(default)]
    pub quantization: Option<Quantization>,
}

/// A converter with `bits` bits over the symmetric range [-full_scale,
/// full_scale]: codes -(2^(bits-1) - 1) ..= 2^(bits-1) - 1 times the step
/// full_scale / (2^(bits-1) - 1), so zero and both range ends are exact
/// levels (the most negative two's-complement code is left unused).
/// Values beyond the range clip to its ends.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(rename = "QuantizationSpec", deny_unknown_fields)]
pub struct Quantization {
    /// Bits of the converter, sign included.
    pub bits: u32,
    /// Full scale of the converter, in the channel's SI unit (m or N).
    pub full_scale: f64,
}

/// Why an instrument chain is not usable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InstrumentError {
    #[error("sensor chain: {name} must be {requirement} (got {value})")]
    Setting {
        name: &'static str,
        value: f64,
        requirement: &'static str,
    },
}

impl Quantization {
    /// Largest code, 2^(bits-1) - 1.
    fn max_code(&self) -> f64 {
        ((1u64 << (self.bits - 1)) - 1) as f64
    }

    /// The step between levels (one LSB).
    pub fn lsb(&self) -> f64 {
        self.full_scale / self.max_code()
    }

    /// The nearest level, clipped to [-full_scale, full_scale].
    pub fn quantize(&self, v: f64) -> f64 {
        let max = self.max_code();
        (v / self.lsb()).round().clamp(-max, max) * self.lsb()
    }
}

impl Sensor {
    /// An ideal sensor in `unit`: the true signal.
    pub fn ideal(unit: Unit) -> Self {
        Self {
            unit,
            noise_rms: 0.0,
            delay_s: 0.0,
            offset: 0.0,
            drift_per_s: 0.0,
            quantization: None,
        }
    }

    pub fn validate(&self) -> Result<(), InstrumentError> {
        let bad = |name, value, requirement| {
            Err(InstrumentError::Setting {
                name,
                value,
                requirement,
            })
        };
        if !(self.noise_rms.is_finite() && self.noise_rms >= 0.0) {
            return bad("noise_rms", self.noise_rms, "finite and non-negative");
        }
        if !self.offset.is_finite() {
            return bad("offset", self.offset, "finite");
        }
        if !self.drift_per_s.is_finite() {
            return bad("drift_per_s", self.drift_per_s, "finite");
        }
        if let Some(q) = self.quantization {
            if !(2..=53).contains(&q.bits) {
                return bad("quantization.bits", q.bits as f64, "between 2 and 53");
            }
            if !(q.full_scale.is_finite() && q.full_scale > 0.0) {
                return bad(
                    "quantization.full_scale",
                    q.full_scale,
                    "positive and finite",
                );
            }
        }
        Ok(())
    }
}

/// The logged signal:
/// `quantize(signal[k] + offset + drift_per_s t_k + noise_rms n_k)` with
/// `t_k = k / sample_rate_hz` and `n_k` standard normal, drawn from `rng` in
/// sample order (no draws when `noise_rms` is zero).
pub fn apply(
    signal: &[f64],
    chain: &Sensor,
    sample_rate_hz: f64,
    rng: &mut impl Rng,
) -> Result<Vec<f64>, InstrumentError> {
    chain.validate()?;
    if !(sample_rate_hz.is_finite() && sample_rate_hz > 0.0) {
        return Err(InstrumentError::Setting {
            name: "sample_rate_hz",
            value: sample_rate_hz,
            requirement: "positive and finite",
        });
    }
    let dt = 1.0 / sample_rate_hz;
    Ok(signal
        .iter()
        .enumerate()
        .map(|(k, &s)| {
            let mut v = s + chain.offset + chain.drift_per_s * (k as f64 * dt);
            if chain.noise_rms > 0.0 {
                let n: f64 = rng.sample(StandardNormal);
                v += chain.noise_rms * n;
            }
            match chain.quantization {
                Some(q) => q.quantize(v),
                None => v,
            }
        })
        .collect())
}

/// The random stream of channel `channel` under campaign seed `seed`:
/// independent across channels, identical for the same (seed, channel).
pub fn channel_rng(seed: u64, channel: &str) -> ChaCha8Rng {
    super::seeded_rng(seed, &format!("channel/{channel}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn noisy() -> Sensor {
        Sensor {
            noise_rms: 1e-5,
            offset: 2e-4,
            drift_per_s: 1e-5,
            ..Sensor::ideal(Unit::Meter)
        }
    }

    #[test]
    fn same_seed_same_bytes_other_seed_or_channel_other_noise() {
        let signal: Vec<f64> = (0..5000).map(|k| (k as f64 * 0.01).sin() * 1e-3).collect();
        let run =
            |seed, ch: &str| apply(&signal, &noisy(), 1000.0, &mut channel_rng(seed, ch)).unwrap();
        let bits = |v: &[f64]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
        assert_eq!(bits(&run(42, "x1")), bits(&run(42, "x1")));
        for other in [run(43, "x1"), run(42, "force")] {
            let a = run(42, "x1");
            // Two independent noise sequences differ in every sample, by
            // sqrt(2) noise_rms in rms.
            let diff: Vec<f64> = a.iter().zip(&other).map(|(p, q)| p - q).collect();
            assert!(diff.iter().all(|d| *d != 0.0));
            let rms = (diff.iter().map(|d| d * d).sum::<f64>() / diff.len() as f64).sqrt();
            assert_relative_eq!(rms, 2f64.sqrt() * 1e-5, max_relative = 0.05);
        }
    }

    #[test]
    fn noise_offset_and_drift_have_their_statistics() {
        // Zero signal: mean of (y - offset - drift t) ~ 0 and its rms ~
        // noise_rms, within 4 standard errors for 1e5 samples (sigma /
        // sqrt(n) for the mean, sigma / sqrt(2n) for the rms).
        let n = 100_000;
        let fs = 1000.0;
        let y = apply(&vec![0.0; n], &noisy(), fs, &mut channel_rng(7, "x1")).unwrap();
        let resid: Vec<f64> = y
            .iter()
            .enumerate()
            .map(|(k, v)| v - 2e-4 - 1e-5 * k as f64 / fs)
            .collect();
        let mean = resid.iter().sum::<f64>() / n as f64;
        let rms = (resid.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
        let sigma = 1e-5;
        assert!(mean.abs() < 4.0 * sigma / (n as f64).sqrt(), "mean {mean}");
        assert!(
            (rms - sigma).abs() < 4.0 * sigma / (2.0 * n as f64).sqrt(),
            "rms {rms}"
        );
        // Without noise the chain is deterministic: offset + drift exactly.
        let ideal = Sensor {
            noise_rms: 0.0,
            ..noisy()
        };
        let y = apply(&[1.0, 1.0], &ideal, 10.0, &mut channel_rng(0, "a")).unwrap();
        assert_relative_eq!(y[1], 1.0 + 2e-4 + 1e-5 * 0.1, max_relative = 1e-15);
    }

    #[test]
    fn quantisation_error_is_at_most_half_an_lsb_and_clips_at_full_scale() {
        let q = Quantization {
            bits: 18,
            full_scale: 0.01,
        };
        // 18 bits over +-10 mm: 131071 steps of 7.63e-8 m per side.
        assert_relative_eq!(q.lsb(), 0.01 / 131_071.0, max_relative = 1e-15);
        let chain = Sensor {
            quantization: Some(q),
            ..Sensor::ideal(Unit::Meter)
        };
        let signal: Vec<f64> = (0..20_001)
            .map(|k| -0.012 + 0.024 * k as f64 / 20_000.0)
            .collect();
        let y = apply(&signal, &chain, 1.0, &mut channel_rng(0, "x1")).unwrap();
        for (s, v) in signal.iter().zip(&y) {
            if s.abs() <= 0.01 {
                assert!((v - s).abs() <= 0.5 * q.lsb() * (1.0 + 1e-9), "{s} -> {v}");
                // On the grid: v / lsb is an integer.
                let code = v / q.lsb();
                assert!((code - code.round()).abs() < 1e-6);
            } else {
                assert_relative_eq!(v.abs(), 0.01, max_relative = 1e-15);
                assert_eq!(v.signum(), s.signum());
            }
        }
        // Zero is a level.
        assert_eq!(q.quantize(0.1 * q.lsb()), 0.0);
        // Three bits: levels -3..3 steps of full_scale / 3.
        let q3 = Quantization {
            bits: 3,
            full_scale: 3.0,
        };
        for (v, want) in [
            (0.49, 0.0),
            (0.51, 1.0),
            (-1.6, -2.0),
            (2.9, 3.0),
            (7.0, 3.0),
            (-9.0, -3.0),
        ] {
            assert_relative_eq!(q3.quantize(v), want, epsilon = 1e-15);
        }
    }

    #[test]
    fn bad_settings_are_named() {
        let msg = |c: Sensor| {
            apply(&[0.0], &c, 1.0, &mut channel_rng(0, "x"))
                .unwrap_err()
                .to_string()
        };
        assert_eq!(
            msg(Sensor {
                noise_rms: -1.0,
                ..Sensor::ideal(Unit::Meter)
            }),
            "sensor chain: noise_rms must be finite and non-negative (got -1)"
        );
        assert_eq!(
            msg(Sensor {
                quantization: Some(Quantization {
                    bits: 1,
                    full_scale: 1.0
                }),
                ..Sensor::ideal(Unit::Meter)
            }),
            "sensor chain: quantization.bits must be between 2 and 53 (got 1)"
        );
        assert_eq!(
            msg(Sensor {
                quantization: Some(Quantization {
                    bits: 16,
                    full_scale: 0.0
                }),
                ..Sensor::ideal(Unit::Meter)
            }),
            "sensor chain: quantization.full_scale must be positive and finite (got 0)"
        );
    }
}
