//! Estimator settings from TOML files, with documented per-dataset defaults in
//! `host-sim/configs/<family>.toml` (compiled in). A file given on the command line is
//! laid over the defaults: it only needs the keys it changes.

use super::AssociationMode;
use anyhow::{Context, Result, bail};
use microslam::association::AssociationConfig;
use microslam::ekf::EkfConfig;
use microslam::ekf::health::HealthConfig;
use microslam::gate::{ChiSquareGate, chi_square_quantile};
use microslam::geometry::Pose2;
use microslam::motion::{Ackermann, AckermannNoise, IncrementNoise, VelocityNoise};
use microslam::scalar::Real;
use microslam::sensors::range_bearing::RangeBearingSensor;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Built-in defaults per dataset family.
const BUILTIN: &[(&str, &str)] = &[
    ("mrclam", include_str!("../../configs/mrclam.toml")),
    ("sim", include_str!("../../configs/sim.toml")),
    ("landmarks", include_str!("../../configs/landmarks.toml")),
];

/// All settings of a landmark-SLAM replay.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settings {
    /// Odometry noise.
    pub odometry: OdometrySettings,
    /// Sighting noise, gate and sensor mount.
    pub sighting: SightingSettings,
    /// Data association.
    pub association: AssociationSettings,
    /// Robust weighting and recovery of the EKF's updates (`[recovery]`; off when absent).
    #[serde(default)]
    pub recovery: RecoverySettings,
    /// Noise of odometry increments (`[increment]`; zero when absent: the recordings
    /// with built-in settings report velocities).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub increment: Option<IncrementSettings>,
    /// A car's wheelbase, steering limit and speed/steering noise (`[vehicle]`): needed by
    /// `ackermann` records of a plain landmark log.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vehicle: Option<VehicleSettings>,
    /// Simulator scenario (only in `sim.toml`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scenario: Option<Scenario>,
    /// Share of the odometry records, or of the sightings that reach the filter, a run may
    /// lose (refused as implausible, out of range, refused by the filter) before it says
    /// so on stderr and in `metrics.json` (`inputs.warnings`); a top-level key, default
    /// [`crate::domain::grid::LOSS_WARNING_FRACTION`] (10 %), as in the grid settings.
    #[serde(default = "loss_warning_fraction")]
    pub loss_warning_fraction: f64,
}

fn loss_warning_fraction() -> f64 {
    crate::domain::grid::LOSS_WARNING_FRACTION
}

/// Noise of odometry increments (`microslam::motion::IncrementNoise`; see
/// `configs/landmarks.toml`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(missing_docs)]
pub struct IncrementSettings {
    pub translation_std: f64,
    pub translation_std_per_metre: f64,
    pub rotation_std: f64,
    pub rotation_std_per_radian: f64,
    pub rotation_std_per_metre: f64,
}

/// A car (`microslam::motion::Ackermann`; see `configs/landmarks.toml`). The sensor's
/// offset ahead of the rear axle is `[sighting] mount`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(missing_docs)]
pub struct VehicleSettings {
    pub wheelbase_m: f64,
    pub max_steering_rad: f64,
    pub speed_std: f64,
    pub speed_std_per_mps: f64,
    pub steering_std: f64,
    pub steering_std_per_mps: f64,
}

/// See `configs/mrclam.toml` for the meaning of each field.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(missing_docs)]
pub struct OdometrySettings {
    pub linear_std: f64,
    pub linear_std_per_mps: f64,
    pub angular_std: f64,
    pub angular_std_per_radps: f64,
    pub angular_std_per_mps: f64,
    pub max_gap_s: f64,
    /// Odometry reporting a faster speed (m/s) is refused as an outlier.
    #[serde(default = "unlimited")]
    pub max_speed_mps: f64,
    /// Odometry reporting a faster turn (rad/s) is refused as an outlier.
    #[serde(default = "unlimited")]
    pub max_turn_rate_radps: f64,
    /// Prior standard deviation of the odometry's speed scale factor, estimated as a
    /// state of the filter (0: not estimated; with `turn_scale_std`).
    #[serde(default)]
    pub speed_scale_std: f64,
    /// Prior standard deviation of the odometry's turn-rate scale factor, estimated as a
    /// state of the filter (0: not estimated; with `speed_scale_std`).
    #[serde(default)]
    pub turn_scale_std: f64,
    /// The odometry's latency (s): a sample stamped `t` describes the motion from
    /// `t + latency_s` on (a robot that reports its commanded velocities before it
    /// drives them). 0: none.
    #[serde(default)]
    pub latency_s: f64,
    /// Between two odometry samples the velocity goes linearly from one to the other
    /// (`true`) or the first is held (`false`, the default).
    #[serde(default)]
    pub interpolate: bool,
}

impl OdometrySettings {
    /// `true` when the odometry scale factors are estimated (either prior is positive).
    pub fn estimates_scale(&self) -> bool {
        self.speed_scale_std > 0.0 || self.turn_scale_std > 0.0
    }
}

fn unlimited() -> f64 {
    f64::INFINITY
}

/// See `configs/mrclam.toml` for the meaning of each field.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(missing_docs)]
pub struct SightingSettings {
    pub range_std: f64,
    pub bearing_std: f64,
    pub update_gate_probability: f64,
    pub min_range: f64,
    pub max_range: f64,
    pub mount: [f64; 3],
    /// Prior standard deviation of the range bias offset `b₀` (m), estimated as a state
    /// (0: not estimated; with `range_bias_curvature_std`).
    #[serde(default)]
    pub range_bias_offset_std: f64,
    /// Prior standard deviation of the range bias curvature `b₂` (m/rad²), estimated as
    /// a state (0: not estimated; with `range_bias_offset_std`).
    #[serde(default)]
    pub range_bias_curvature_std: f64,
    /// Prior mean of `b₀` (m) when the range bias is estimated: a calibration made
    /// beforehand (default 0).
    #[serde(default)]
    pub range_bias_offset_mean: f64,
    /// Prior mean of `b₂` (m/rad²) when the range bias is estimated (default 0).
    #[serde(default)]
    pub range_bias_curvature_mean: f64,
}

impl SightingSettings {
    /// `true` when the range bias is estimated (either prior is positive).
    pub fn estimates_bias(&self) -> bool {
        self.range_bias_offset_std > 0.0 || self.range_bias_curvature_std > 0.0
    }

    /// `true` when the range bias' prior mean is not zero.
    pub fn has_bias_mean(&self) -> bool {
        self.range_bias_offset_mean != 0.0 || self.range_bias_curvature_mean != 0.0
    }
}

/// See `configs/mrclam.toml` for the meaning of each field.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(missing_docs)]
pub struct AssociationSettings {
    pub mode: AssociationMode,
    pub individual_probability: f64,
    pub new_landmark_probability: f64,
    pub joint_probability: f64,
    pub max_search_nodes: u32,
    pub batch_window_s: f64,
    pub ambiguity_margin: f64,
    pub distinct_in_batch: bool,
}

/// `[recovery]`: the fields of [`microslam::ekf::health::HealthConfig`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecoverySettings {
    /// Innovations beyond this many standard deviations are down-weighted (Huber); 0: off.
    pub huber_sigma: f64,
    /// Gate refusals in a row that declare the filter lost; 0: no recovery.
    pub lost_after: u16,
    /// Standard deviation added to x and y at a recovery, m.
    pub position_std: f64,
    /// Standard deviation added to the heading at a recovery, rad.
    pub heading_std: f64,
    /// Sightings the lost flag's surprise rate averages over; 0: no lost flag.
    #[serde(default)]
    pub lost_memory: u16,
    /// Surprise rate above which the lost flag is raised.
    #[serde(default = "one")]
    pub lost_rate: f64,
}

fn one() -> f64 {
    1.0
}

impl Default for RecoverySettings {
    /// Off: no weighting, no recovery.
    fn default() -> Self {
        Self {
            huber_sigma: 0.0,
            lost_after: 0,
            position_std: 0.0,
            heading_std: 0.0,
            lost_memory: 0,
            lost_rate: 1.0,
        }
    }
}

/// Largest noise figure of a landmark settings file, in its unit (m, m/s, rad/s, or per
/// m/s, per rad/s, a scale): beyond it a value is a typo, not a noise model.
pub const MAX_NOISE_STD: f64 = 100.0;
/// Longest odometry latency a landmark settings file may give, seconds.
pub const MAX_LATENCY_S: f64 = 10.0;

impl Settings {
    /// The built-in defaults of a dataset family (`mrclam`, `sim`).
    pub fn builtin(family: &str) -> Result<Self> {
        let text = builtin_text(family)?;
        toml::from_str(text).with_context(|| format!("built-in config {family}.toml"))
    }

    /// The defaults of `family` with the file `path` (if any) laid over them, for the
    /// association `mode` (`None`: the file's own `association.mode`).
    ///
    /// With an unknown-id mode (ICNN, JCBB), the `[unknown_ids]` table, when present, is
    /// laid over the rest: association needs noise figures that keep the filter
    /// consistent, which are not always those that score best with known ids. The layers,
    /// each over the ones before it: the built-in settings, the built-in `[unknown_ids]`
    /// (unknown ids only), the file, the file's `[unknown_ids]` (unknown ids only), and
    /// `mode`. So a key the file sets is never undone by the built-in overlay: with
    /// `-a jcbb`, a file (or a `sweep` grid) with `[sighting] range_std = 0.4` runs with
    /// 0.4.
    pub fn load_for(
        family: &str,
        path: Option<&Path>,
        mode: Option<AssociationMode>,
    ) -> Result<Self> {
        let over = match path {
            Some(path) => {
                let text = std::fs::read_to_string(path)
                    .with_context(|| format!("cannot read config {}", path.display()))?;
                toml::from_str(&text).with_context(|| format!("config {}", path.display()))?
            }
            None => toml::Table::new(),
        };
        let origin = match path {
            Some(p) => format!("config {}", p.display()),
            None => format!("built-in config {family}.toml"),
        };
        Self::load_over(family, over, mode, &origin)
    }

    /// Like [`Settings::load_for`] with the overrides already parsed (`over`, laid over
    /// the built-in defaults); `origin` names them in errors.
    pub fn load_over(
        family: &str,
        mut over: toml::Table,
        mode: Option<AssociationMode>,
        origin: &str,
    ) -> Result<Self> {
        let mut base: toml::Table = toml::from_str(builtin_text(family)?)?;
        let builtin_unknown = base.remove("unknown_ids");
        let over_unknown = over.remove("unknown_ids");
        let mode_of = |t: &toml::Table| {
            t.get("association")
                .and_then(|a| a.get("mode"))
                .and_then(|m| m.as_str())
                .map(str::to_owned)
        };
        let unknown_ids = match mode {
            Some(mode) => mode != AssociationMode::Known,
            None => mode_of(&over)
                .or_else(|| mode_of(&base))
                .is_some_and(|m| m != "known"),
        };
        if unknown_ids && let Some(toml::Value::Table(t)) = builtin_unknown {
            merge(&mut base, t);
        }
        merge(&mut base, over);
        if unknown_ids && let Some(toml::Value::Table(t)) = over_unknown {
            merge(&mut base, t);
        }
        if let Some(mode) = mode {
            let mut table = toml::Table::new();
            table.insert("mode".into(), toml::Value::try_from(mode)?);
            merge(
                &mut base,
                toml::Table::from_iter([("association".to_owned(), toml::Value::Table(table))]),
            );
        }
        let settings: Self = toml::Value::Table(base)
            .try_into()
            .with_context(|| origin.to_owned())?;
        settings.validate().with_context(|| origin.to_owned())?;
        Ok(settings)
    }

    /// [`Settings::load_for`] with the association mode of the files.
    pub fn load(family: &str, path: Option<&Path>) -> Result<Self> {
        Self::load_for(family, path, None)
    }

    /// Checks ranges of values that TOML types cannot; the error names the setting as the
    /// settings file spells it.
    pub fn validate(&self) -> Result<()> {
        if !(0.0..=1.0).contains(&self.loss_warning_fraction) {
            bail!(
                "loss_warning_fraction = {} must be within 0 ..= 1",
                self.loss_warning_fraction
            );
        }
        let o = &self.odometry;
        let s = &self.sighting;
        let a = &self.association;
        let non_negative = [
            ("odometry.linear_std", o.linear_std),
            ("odometry.linear_std_per_mps", o.linear_std_per_mps),
            ("odometry.angular_std", o.angular_std),
            ("odometry.angular_std_per_radps", o.angular_std_per_radps),
            ("odometry.angular_std_per_mps", o.angular_std_per_mps),
            ("odometry.speed_scale_std", o.speed_scale_std),
            ("odometry.turn_scale_std", o.turn_scale_std),
            ("odometry.latency_s", o.latency_s),
            ("sighting.range_std", s.range_std),
            ("sighting.bearing_std", s.bearing_std),
            ("sighting.range_bias_offset_std", s.range_bias_offset_std),
            (
                "sighting.range_bias_curvature_std",
                s.range_bias_curvature_std,
            ),
            ("sighting.min_range", s.min_range),
            ("association.batch_window_s", a.batch_window_s),
            ("association.ambiguity_margin", a.ambiguity_margin),
        ];
        if let Some((name, v)) = non_negative
            .iter()
            .find(|(_, v)| !(v.is_finite() && *v >= 0.0))
        {
            bail!(
                "{name} = {v}: noise figures, ranges and windows must be finite and non-negative"
            );
        }
        // Finite and non-negative, but beyond any physical range: a typo (1e30), not a
        // noise model. The bounds are stated in docs/guide.md.
        let bounded = [
            ("odometry.linear_std", o.linear_std, MAX_NOISE_STD),
            (
                "odometry.linear_std_per_mps",
                o.linear_std_per_mps,
                MAX_NOISE_STD,
            ),
            ("odometry.angular_std", o.angular_std, MAX_NOISE_STD),
            (
                "odometry.angular_std_per_radps",
                o.angular_std_per_radps,
                MAX_NOISE_STD,
            ),
            (
                "odometry.angular_std_per_mps",
                o.angular_std_per_mps,
                MAX_NOISE_STD,
            ),
            ("odometry.speed_scale_std", o.speed_scale_std, MAX_NOISE_STD),
            ("odometry.turn_scale_std", o.turn_scale_std, MAX_NOISE_STD),
            ("odometry.latency_s", o.latency_s, MAX_LATENCY_S),
            ("sighting.range_std", s.range_std, MAX_NOISE_STD),
            ("sighting.bearing_std", s.bearing_std, core::f64::consts::PI),
            (
                "sighting.range_bias_offset_std",
                s.range_bias_offset_std,
                MAX_NOISE_STD,
            ),
            (
                "sighting.range_bias_curvature_std",
                s.range_bias_curvature_std,
                MAX_NOISE_STD,
            ),
        ];
        if let Some((name, v, max)) = bounded.iter().find(|(_, v, max)| v > max) {
            bail!("{name} = {v}: beyond any physical range (0 ..= {max})");
        }
        if !(s.range_bias_offset_mean.is_finite() && s.range_bias_curvature_mean.is_finite()) {
            bail!("sighting.range_bias_offset_mean and range_bias_curvature_mean must be finite");
        }
        if s.has_bias_mean() && !s.estimates_bias() {
            bail!(
                "sighting.range_bias_offset_mean / range_bias_curvature_mean need \
                 range_bias_offset_std or range_bias_curvature_std > 0 (the bias is a state)"
            );
        }
        if !(o.max_speed_mps > 0.0 && o.max_turn_rate_radps > 0.0) {
            bail!("max_speed_mps and max_turn_rate_radps must be positive");
        }
        if !(o.max_gap_s.is_finite() && o.max_gap_s > 0.0 && s.max_range > s.min_range) {
            bail!("max_gap_s must be positive and max_range > min_range");
        }
        for p in [
            s.update_gate_probability,
            a.individual_probability,
            a.new_landmark_probability,
            a.joint_probability,
        ] {
            if !(p > 0.0 && p < 1.0) {
                bail!("probabilities must be inside (0, 1), got {p}");
            }
        }
        if a.new_landmark_probability < a.individual_probability {
            bail!("new_landmark_probability must not be below individual_probability");
        }
        let r = &self.recovery;
        let recovery = [
            ("recovery.huber_sigma", r.huber_sigma),
            ("recovery.position_std", r.position_std),
            ("recovery.heading_std", r.heading_std),
            ("recovery.lost_rate", r.lost_rate),
        ];
        if let Some((name, v)) = recovery.iter().find(|(_, v)| !(v.is_finite() && *v >= 0.0)) {
            bail!("{name} = {v}: must be finite and non-negative");
        }
        if s.mount.iter().any(|v| !v.is_finite()) {
            bail!("sensor mount must be finite");
        }
        if let Some(i) = &self.increment {
            let figures = [
                ("increment.translation_std", i.translation_std),
                (
                    "increment.translation_std_per_metre",
                    i.translation_std_per_metre,
                ),
                ("increment.rotation_std", i.rotation_std),
                (
                    "increment.rotation_std_per_radian",
                    i.rotation_std_per_radian,
                ),
                ("increment.rotation_std_per_metre", i.rotation_std_per_metre),
            ];
            if let Some((name, v)) = figures
                .iter()
                .find(|(_, v)| !(v.is_finite() && (0.0..=MAX_NOISE_STD).contains(v)))
            {
                bail!("{name} = {v}: must be finite, within 0 ..= {MAX_NOISE_STD}");
            }
        }
        if let Some(bad) = self.vehicle::<f64>().and_then(|v| v.invalid_setting()) {
            bail!("vehicle.{}: {}", Self::vehicle_key(bad.name), bad.rule);
        }
        if let Some(v) = &self.vehicle {
            let figures = [
                ("vehicle.speed_std", v.speed_std),
                ("vehicle.speed_std_per_mps", v.speed_std_per_mps),
                ("vehicle.steering_std", v.steering_std),
                ("vehicle.steering_std_per_mps", v.steering_std_per_mps),
            ];
            if let Some((name, x)) = figures.iter().find(|(_, x)| *x > MAX_NOISE_STD) {
                bail!("{name} = {x}: beyond any physical range (0 ..= {MAX_NOISE_STD})");
            }
        }
        // The filter can run in `f32` (`--precision f32`) and the firmware does: a value
        // valid as an `f64` may still be beyond `f32`'s range (≈ 3.4e38).
        let in_f32 = self.ekf_config::<f32>().invalid_setting();
        if let Some(bad) = in_f32.or_else(|| self.health_config::<f32>().invalid_setting()) {
            bail!(
                "{}: beyond the range of f32, in which the filter can run (--precision f32) \
                 and the firmware does: {bad}",
                Self::key_of(bad.name)
            );
        }
        Ok(())
    }

    /// The settings file's key of a field of the library's [`EkfConfig`] or
    /// [`HealthConfig`], as their `invalid_setting` names it.
    fn key_of(field: &str) -> String {
        match field {
            "range_std" | "bearing_std" | "mount" => format!("sighting.{field}"),
            "gate" => "sighting.update_gate_probability".to_owned(),
            "huber_sigma" => "recovery.huber_sigma".to_owned(),
            "recovery_position_std" => "recovery.position_std".to_owned(),
            "recovery_heading_std" => "recovery.heading_std".to_owned(),
            "lost_rate" => "recovery.lost_rate".to_owned(),
            // The velocity noise's fields, as [odometry] spells them.
            other => format!("odometry.{other}"),
        }
    }

    /// The settings file's key in `[vehicle]` of a field [`Ackermann::invalid_setting`]
    /// names.
    fn vehicle_key(field: &str) -> &str {
        match field {
            "wheelbase" => "wheelbase_m",
            "max_steering" => "max_steering_rad",
            other => other,
        }
    }

    /// The car of `[vehicle]` in scalar `T`, `None` when the settings have none.
    pub fn vehicle<T: Real>(&self) -> Option<Ackermann<T>> {
        let v = self.vehicle.as_ref()?;
        let l = T::lit;
        Some(Ackermann {
            wheelbase: l(v.wheelbase_m),
            max_steering: l(v.max_steering_rad),
            noise: AckermannNoise {
                speed_std: l(v.speed_std),
                speed_std_per_mps: l(v.speed_std_per_mps),
                steering_std: l(v.steering_std),
                steering_std_per_mps: l(v.steering_std_per_mps),
            },
        })
    }

    /// The EKF configuration in scalar `T`.
    pub fn ekf_config<T: Real>(&self) -> EkfConfig<T> {
        let o = &self.odometry;
        let s = &self.sighting;
        let l = T::lit;
        EkfConfig {
            // `[increment]`, zero noise without it (velocity odometry uses none).
            increment_noise: match &self.increment {
                Some(i) => IncrementNoise {
                    translation_std: l(i.translation_std),
                    translation_std_per_metre: l(i.translation_std_per_metre),
                    rotation_std: l(i.rotation_std),
                    rotation_std_per_radian: l(i.rotation_std_per_radian),
                    rotation_std_per_metre: l(i.rotation_std_per_metre),
                },
                None => IncrementNoise {
                    translation_std: T::ZERO,
                    translation_std_per_metre: T::ZERO,
                    rotation_std: T::ZERO,
                    rotation_std_per_radian: T::ZERO,
                    rotation_std_per_metre: T::ZERO,
                },
            },
            velocity_noise: VelocityNoise {
                linear_std: l(o.linear_std),
                linear_std_per_mps: l(o.linear_std_per_mps),
                angular_std: l(o.angular_std),
                angular_std_per_radps: l(o.angular_std_per_radps),
                angular_std_per_mps: l(o.angular_std_per_mps),
            },
            range_std: l(s.range_std),
            bearing_std: l(s.bearing_std),
            sensor: RangeBearingSensor::new(Pose2::new(
                l(s.mount[0]),
                l(s.mount[1]),
                l(s.mount[2]),
            )),
            gate: ChiSquareGate::from_threshold(l(chi_square_quantile(
                s.update_gate_probability,
                2,
            ))),
        }
    }

    /// The self-calibration priors in the order of the wire's `EkfSettings::calibration`:
    /// speed scale, turn-rate scale, range bias offset, range bias curvature (0: off).
    pub fn calibration_priors(&self) -> [f32; 4] {
        let (o, s) = (&self.odometry, &self.sighting);
        [
            o.speed_scale_std,
            o.turn_scale_std,
            s.range_bias_offset_std,
            s.range_bias_curvature_std,
        ]
        .map(|v| v as f32)
    }

    /// The supervision settings of the EKF's updates (`[recovery]`).
    pub fn health_config<T: Real>(&self) -> HealthConfig<T> {
        let r = &self.recovery;
        HealthConfig {
            huber_sigma: T::lit(r.huber_sigma),
            lost_after: r.lost_after,
            recovery_position_std: T::lit(r.position_std),
            recovery_heading_std: T::lit(r.heading_std),
            lost_memory: r.lost_memory,
            lost_rate: T::lit(r.lost_rate),
        }
    }

    /// The association configuration in scalar `T`.
    pub fn association_config<T: Real>(&self) -> AssociationConfig<T> {
        let a = &self.association;
        AssociationConfig {
            individual_gate: ChiSquareGate::from_threshold(T::lit(chi_square_quantile(
                a.individual_probability,
                2,
            ))),
            new_landmark_threshold: T::lit(chi_square_quantile(a.new_landmark_probability, 2)),
            joint_probability: a.joint_probability,
            max_search_nodes: a.max_search_nodes,
            ambiguity_margin: T::lit(a.ambiguity_margin),
            distinct_in_batch: a.distinct_in_batch,
        }
    }
}

/// The built-in settings file of a dataset family, as TOML text.
pub fn builtin_text(family: &str) -> Result<&'static str> {
    BUILTIN
        .iter()
        .find(|(f, _)| *f == family)
        .map(|(_, t)| *t)
        .with_context(|| format!("no built-in config for dataset family `{family}`"))
}

/// Deep merge of TOML tables: values of `over` replace those of `base`.
fn merge(base: &mut toml::Table, over: toml::Table) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

/// The simulated world and drive (section `[scenario]` of `configs/sim.toml`, where each
/// field is documented).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(missing_docs)]
pub struct Scenario {
    pub duration_s: f64,
    pub odometry_rate_hz: f64,
    pub sighting_rate_hz: f64,
    pub landmarks: u32,
    pub field_half_size_m: f64,
    pub min_landmark_spacing_m: f64,
    pub loop_radius_m: f64,
    pub speed_mps: f64,
    pub wobble_radps: f64,
    pub wobble_period_s: f64,
    pub fov_deg: f64,
    pub max_range_m: f64,
    /// `host-sim sim --car`: the car's sensor this far ahead of its rear axle, m.
    #[serde(default)]
    pub car_sensor_ahead_m: f64,
}

#[cfg(test)]
mod tests;
