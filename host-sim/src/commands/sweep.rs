//! `host-sim sweep`: a grid of settings × a list of recordings, replayed in parallel.
//!
//! The grid is a settings file (the format of `--config`) in which any key may hold a list
//! of values, e.g. `[sighting] range_std = [0.1, 0.2]`; the lists are expanded to their
//! Cartesian product, each combination laid over the family's built-in settings. A key
//! whose setting is itself a list (`mount`) takes a list of lists. Every combination is
//! replayed on every recording (rayon, all cores; `RAYON_NUM_THREADS` limits them) and
//! scored against ground truth; the table goes to `sweep.csv` and `sweep.json`, one row
//! per settings × recording, with each combination's mean and worst.

use crate::domain::config::{Settings, builtin_text};
use crate::domain::recording::Recording;
use crate::domain::{AssociationMode, Precision};
use crate::inputs::readers::DatasetSpec;
use crate::metrics::{Metrics, evaluate};
use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Options of `host-sim sweep` (filled by [`crate::cli`]).
#[derive(Debug, Clone)]
pub struct SweepOptions {
    /// The grid: a settings file whose keys may hold lists of values; without it, the
    /// built-in settings alone.
    pub grid: Option<PathBuf>,
    /// Recordings: `mrclam:<dir>/robot<k>` or `mrclam:<dir>/robot<a>-<b>` entries, each
    /// optionally followed by stress variants (`+8hz+turn1.4`, [`crate::inputs::stress`]).
    pub runs: Vec<String>,
    /// Data association (default: from the settings, `known` if none).
    pub association: Option<AssociationMode>,
    /// Scalar the filter runs on.
    pub precision: Precision,
    /// Output folder: sweep.csv, sweep.json.
    pub out: PathBuf,
}

/// One recording of the sweep: the dataset and robot.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RunSpec {
    /// The dataset (`mrclam:dataset6`).
    pub dataset: DatasetSpec,
    /// The robot.
    pub robot: u8,
}

/// Parses `--runs` entries: `mrclam:<dir>/robot<k>`, `mrclam:<dir>/robot<a>-<b>`, or
/// `mrclam:<dir>` (robot 1), each optionally followed by stress variants that apply to
/// every robot of the entry (`mrclam:dataset6/robot1-5+8hz`).
pub fn parse_runs(entries: &[String]) -> Result<Vec<RunSpec>> {
    let mut runs = Vec::new();
    for entry in entries {
        let entry = entry.trim();
        // Stress variants after the robot (`…/robot1-5+8hz`) apply to each robot.
        let (entry, variants) = match entry.split_once('+') {
            Some((e, v)) => (e, format!("+{v}")),
            None => (entry, String::new()),
        };
        if let Some((head, range)) = entry.rsplit_once("/robot")
            && let Some((a, b)) = range.split_once('-')
        {
            let (a, b): (u8, u8) = (
                a.parse()
                    .with_context(|| format!("run `{entry}`: robot `{a}`"))?,
                b.parse()
                    .with_context(|| format!("run `{entry}`: robot `{b}`"))?,
            );
            if a > b {
                bail!("run `{entry}`: empty robot range {a}-{b}");
            }
            for k in a..=b {
                runs.push(parse_run(&format!("{head}/robot{k}{variants}"))?);
            }
        } else {
            runs.push(parse_run(&format!("{entry}{variants}"))?);
        }
    }
    if runs.is_empty() {
        bail!("no recordings given (--runs)");
    }
    Ok(runs)
}

fn parse_run(entry: &str) -> Result<RunSpec> {
    let spec: DatasetSpec = entry.parse().map_err(anyhow::Error::msg)?;
    let DatasetSpec::Mrclam(dir) = &spec else {
        bail!("run `{entry}`: sweeps replay landmark datasets (`mrclam:`) only");
    };
    let (base, variants) = crate::inputs::stress::split(dir)?;
    let (dir, robot) = crate::inputs::readers::mrclam_robot(base, 1)?;
    let suffix: String = variants.iter().map(|v| format!("+{v}")).collect();
    Ok(RunSpec {
        dataset: DatasetSpec::Mrclam(format!("{dir}{suffix}")),
        robot,
    })
}

/// One point of the grid: the chosen value of each varied key, and the overrides.
#[derive(Clone, Debug, PartialEq)]
pub struct GridPoint {
    /// `key = value` for each varied key (dotted paths), in sorted key order.
    pub label: Vec<(String, String)>,
    /// The settings file this point stands for.
    pub overrides: toml::Table,
}

/// Expands `grid` (lists of choices) into its Cartesian product. `base` is the family's
/// built-in settings: where it holds a list (e.g. `mount`), only a list of lists is a
/// choice.
pub fn expand(grid: &toml::Table, base: &toml::Table) -> Vec<GridPoint> {
    let mut axes: Vec<(Vec<String>, Vec<toml::Value>)> = Vec::new();
    collect_axes(grid, base, &mut Vec::new(), &mut axes);
    let mut points = vec![GridPoint {
        label: Vec::new(),
        overrides: grid.clone(),
    }];
    for (path, choices) in &axes {
        let mut next = Vec::with_capacity(points.len() * choices.len());
        for p in &points {
            for c in choices {
                let mut q = p.clone();
                set_path(&mut q.overrides, path, c.clone());
                q.label.push((path.join("."), c.to_string()));
                next.push(q);
            }
        }
        points = next;
    }
    points
}

fn collect_axes(
    table: &toml::Table,
    base: &toml::Table,
    path: &mut Vec<String>,
    axes: &mut Vec<(Vec<String>, Vec<toml::Value>)>,
) {
    for (k, v) in table {
        path.push(k.clone());
        match v {
            toml::Value::Table(t) => {
                let sub = match base.get(k) {
                    Some(toml::Value::Table(b)) => b.clone(),
                    _ => toml::Table::new(),
                };
                collect_axes(t, &sub, path, axes);
            }
            toml::Value::Array(items) => {
                let list_setting = matches!(base.get(k), Some(toml::Value::Array(_)));
                let choices = !list_setting || items.iter().all(|i| i.is_array());
                if choices && !items.is_empty() {
                    axes.push((path.clone(), items.clone()));
                }
            }
            _ => {}
        }
        path.pop();
    }
}

fn set_path(table: &mut toml::Table, path: &[String], value: toml::Value) {
    let Some((last, head)) = path.split_last() else {
        return;
    };
    let mut t = table;
    for k in head {
        let Some(toml::Value::Table(sub)) = t.get_mut(k) else {
            return;
        };
        t = sub;
    }
    t.insert(last.clone(), value);
}

/// One row of the table: one settings point on one recording.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    /// Index of the settings point.
    pub settings: usize,
    /// The point's varied keys and values, `key=value; …`.
    pub label: String,
    /// The recording (`mrclam/dataset6/robot3`).
    pub recording: String,
    /// ATE after an SE(2) alignment, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ate_se2_m: Option<f64>,
    /// Landmark RMSE after the alignment, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub landmark_se2_m: Option<f64>,
    /// Mean pose NEES (3 expected).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nees_mean: Option<f64>,
    /// Share of steps whose pose NEES lies inside the 95 % χ²₃ band.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nees_in_95: Option<f64>,
    /// Mean NIS of accepted sightings (2 expected).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nis_mean: Option<f64>,
    /// Association purity.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub purity: Option<f64>,
    /// Dead-reckoning ATE after the alignment, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dead_reckoning_se2_m: Option<f64>,
    /// Recoveries of the supervision.
    pub recoveries: usize,
    /// Landmarks in the final map.
    pub landmarks_created: usize,
    /// Share of the pose estimates with the lost flag up.
    pub lost_share: f64,
    /// With ground truth: share of the estimates whose lost flag agrees with their error
    /// being above 1 m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lost_flag_agreement: Option<f64>,
}

impl Row {
    fn new(settings: usize, label: &str, m: &Metrics) -> Self {
        Self {
            settings,
            label: label.to_owned(),
            recording: m.dataset.clone(),
            ate_se2_m: m.ate_rmse_m.se2,
            landmark_se2_m: m.landmark_rmse_m.se2,
            nees_mean: m.nees_pose_mean,
            nees_in_95: m.nees_pose_within_95,
            nis_mean: m.nis_mean,
            purity: m.association_purity,
            dead_reckoning_se2_m: m.dead_reckoning_ate_rmse_m.se2,
            recoveries: m.counts.recoveries,
            landmarks_created: m.landmarks_created,
            lost_share: m.lost_share,
            lost_flag_agreement: m.lost_flag_agreement,
        }
    }
}

/// Mean and worst of one settings point over the recordings.
#[derive(Clone, Debug, Serialize)]
pub struct Aggregate {
    /// Index of the settings point.
    pub settings: usize,
    /// Its varied keys and values.
    pub label: String,
    /// Mean ATE(se2) over the recordings, m (∞ when one has none: left out of the JSON).
    #[serde(skip_serializing_if = "not_finite")]
    pub ate_mean_m: f64,
    /// Worst ATE(se2), m (∞ when a recording has none: left out of the JSON).
    #[serde(skip_serializing_if = "not_finite")]
    pub ate_worst_m: f64,
    /// Worst mean pose NEES (∞ when a recording has none: left out of the JSON).
    #[serde(skip_serializing_if = "not_finite")]
    pub nees_worst: f64,
    /// Lowest association purity.
    pub purity_worst: f64,
    /// Recordings scored.
    pub runs: usize,
}

/// Whether `v` is NaN or infinite (a figure left out of the JSON).
fn not_finite(v: &f64) -> bool {
    !v.is_finite()
}

/// The whole table.
#[derive(Clone, Debug, Serialize)]
pub struct Table {
    /// Association mode.
    pub association: AssociationMode,
    /// Scalar.
    pub precision: String,
    /// One row per settings × recording.
    pub rows: Vec<Row>,
    /// Per settings point, sorted by mean ATE.
    pub settings: Vec<Aggregate>,
    /// Wall time of the replays, s.
    pub wall_time_s: f64,
    /// Worker threads used.
    pub threads: usize,
}

/// Aggregates rows per settings point, best mean ATE first (a missing ATE counts as ∞).
pub fn aggregate(rows: &[Row]) -> Vec<Aggregate> {
    let mut out: Vec<Aggregate> = Vec::new();
    for r in rows {
        let ate = r.ate_se2_m.unwrap_or(f64::INFINITY);
        let nees = r.nees_mean.unwrap_or(f64::INFINITY);
        let purity = r.purity.unwrap_or(0.0);
        match out.iter_mut().find(|a| a.settings == r.settings) {
            Some(a) => {
                a.ate_mean_m += ate;
                a.ate_worst_m = a.ate_worst_m.max(ate);
                a.nees_worst = a.nees_worst.max(nees);
                a.purity_worst = a.purity_worst.min(purity);
                a.runs += 1;
            }
            None => out.push(Aggregate {
                settings: r.settings,
                label: r.label.clone(),
                ate_mean_m: ate,
                ate_worst_m: ate,
                nees_worst: nees,
                purity_worst: purity,
                runs: 1,
            }),
        }
    }
    for a in &mut out {
        a.ate_mean_m /= a.runs as f64;
    }
    out.sort_by(|a, b| a.ate_mean_m.total_cmp(&b.ate_mean_m));
    out
}

/// Runs every point of the grid on every recording, in parallel.
pub fn run(
    points: &[GridPoint],
    settings: &[Settings],
    recordings: &[Recording],
    mode: AssociationMode,
    precision: Precision,
    progress: Option<&ProgressBar>,
) -> Result<Vec<Row>> {
    let jobs: Vec<(usize, usize)> = (0..settings.len())
        .flat_map(|s| (0..recordings.len()).map(move |r| (s, r)))
        .collect();
    let mut rows = jobs
        .par_iter()
        .map(|&(s, r)| -> Result<Row> {
            let (Some(set), Some(rec), Some(point)) =
                (settings.get(s), recordings.get(r), points.get(s))
            else {
                bail!("sweep job out of range");
            };
            let run = crate::drivers::ekf::replay(rec, set, mode, precision, None)?;
            let m = evaluate(rec, &run);
            if let Some(p) = progress {
                p.inc(1);
            }
            Ok(Row::new(s, &label_text(point), &m))
        })
        .collect::<Result<Vec<_>>>()?;
    rows.sort_by(|a, b| (a.settings, &a.recording).cmp(&(b.settings, &b.recording)));
    Ok(rows)
}

fn label_text(p: &GridPoint) -> String {
    if p.label.is_empty() {
        return "(built-in)".to_owned();
    }
    p.label
        .iter()
        .map(|(k, v)| format!("{k}={v}"))
        .collect::<Vec<_>>()
        .join("; ")
}

/// `host-sim sweep`.
pub fn run_cli(args: &SweepOptions, quiet: bool) -> Result<()> {
    let runs = parse_runs(&args.runs)?;
    let family = runs.first().map_or("mrclam", |r| r.dataset.family());
    let grid: toml::Table = match &args.grid {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read grid {}", p.display()))?;
            toml::from_str(&text).with_context(|| format!("grid {}", p.display()))?
        }
        None => toml::Table::new(),
    };
    let base: toml::Table = toml::from_str(builtin_text(family)?)?;
    let points = expand(&grid, &base);
    let origin = args
        .grid
        .as_ref()
        .map_or_else(|| "built-in".to_owned(), |p| p.display().to_string());
    let settings = points
        .iter()
        .map(|p| {
            Settings::load_over(
                family,
                p.overrides.clone(),
                args.association,
                &format!("grid {origin}, point {}", label_text(p)),
            )
        })
        .collect::<Result<Vec<_>>>()?;
    let mode = args
        .association
        .or_else(|| settings.first().map(|s| s.association.mode))
        .unwrap_or(AssociationMode::Known);
    let recordings = runs
        .par_iter()
        .map(|r| crate::inputs::readers::read(&r.dataset, r.robot))
        .collect::<Result<Vec<_>>>()?;
    let total = (points.len() * recordings.len()) as u64;
    let progress = (!quiet).then(|| {
        let bar = ProgressBar::new(total);
        if let Ok(style) =
            ProgressStyle::with_template("{spinner} sweep [{bar:40}] {pos}/{len} runs ({eta})")
        {
            bar.set_style(style.progress_chars("=> "));
        }
        bar
    });
    let started = Instant::now();
    let rows = run(
        &points,
        &settings,
        &recordings,
        mode,
        args.precision,
        progress.as_ref(),
    )?;
    if let Some(p) = &progress {
        p.finish_and_clear();
    }
    let table = Table {
        association: mode,
        precision: format!("{:?}", args.precision).to_lowercase(),
        settings: aggregate(&rows),
        rows,
        wall_time_s: started.elapsed().as_secs_f64(),
        threads: rayon::current_num_threads(),
    };
    write(&args.out, &table)?;
    if !quiet {
        println!("{}", summary(&table, &args.out));
    }
    Ok(())
}

/// Writes `sweep.csv` and `sweep.json` into `out`.
pub fn write(out: &Path, table: &Table) -> Result<()> {
    crate::output::create_folder(out)?;
    std::fs::write(out.join("sweep.csv"), csv(table))
        .with_context(|| format!("cannot write {}", out.join("sweep.csv").display()))?;
    crate::output::write_report(&out.join("sweep.json"), table)
}

/// The rows as CSV (a header line; text fields quoted, empty cells for missing figures).
pub fn csv(table: &Table) -> String {
    let mut s = String::from(
        "settings,label,recording,ate_se2_m,landmark_se2_m,nees_mean,nees_in_95,nis_mean,purity,dead_reckoning_se2_m,recoveries,landmarks_created,lost_share,lost_flag_agreement\n",
    );
    let f = |v: Option<f64>| v.map_or_else(String::new, |v| format!("{v:.6}"));
    let q = |t: &str| format!("\"{}\"", t.replace('"', "\"\""));
    for r in &table.rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{},{:.6},{}",
            r.settings,
            q(&r.label),
            q(&r.recording),
            f(r.ate_se2_m),
            f(r.landmark_se2_m),
            f(r.nees_mean),
            f(r.nees_in_95),
            f(r.nis_mean),
            f(r.purity),
            f(r.dead_reckoning_se2_m),
            r.recoveries,
            r.landmarks_created,
            r.lost_share,
            f(r.lost_flag_agreement)
        );
    }
    s
}

/// A one-screen summary: the best settings points by mean ATE, with their worst run.
pub fn summary(table: &Table, out: &Path) -> String {
    let mut s = String::new();
    let runs = table.settings.first().map_or(0, |a| a.runs);
    let _ = writeln!(
        s,
        "sweep: {} settings × {} runs ({:?}, {}) in {:.1} s on {} threads",
        table.settings.len(),
        runs,
        table.association,
        table.precision,
        table.wall_time_s,
        table.threads
    );
    let _ = writeln!(
        s,
        "{:>4} {:>9} {:>9} {:>9} {:>7}  settings",
        "#", "ATE mean", "ATE worst", "NEES max", "purity"
    );
    for a in table.settings.iter().take(12) {
        let mut label = a.label.clone();
        if label.chars().count() > 90 {
            label = label.chars().take(87).collect::<String>() + "...";
        }
        let _ = writeln!(
            s,
            "{:>4} {:>9.3} {:>9.3} {:>9.1} {:>7.2}  {}",
            a.settings, a.ate_mean_m, a.ate_worst_m, a.nees_worst, a.purity_worst, label
        );
    }
    if table.settings.len() > 12 {
        let _ = writeln!(s, "… {} more", table.settings.len() - 12);
    }
    let _ = write!(
        s,
        "table: {}, {}",
        out.join("sweep.csv").display(),
        out.join("sweep.json").display()
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(text: &str) -> toml::Table {
        toml::from_str(text).unwrap()
    }

    #[test]
    fn lists_expand_to_their_cartesian_product() {
        let base = table("[sighting]\nrange_std = 0.1\nmount = [0.0, 0.0, 0.0]\n");
        let grid = table(
            "[sighting]\nrange_std = [0.1, 0.2, 0.3]\nmount = [0.0, 0.1, 0.0]\n\
             [odometry]\nlinear_std = [0.01, 0.03]\n",
        );
        let points = expand(&grid, &base);
        assert_eq!(points.len(), 6, "mount is one value, not three choices");
        let ranges: Vec<f64> = points
            .iter()
            .map(|p| p.overrides["sighting"]["range_std"].as_float().unwrap())
            .collect();
        // Keys vary in sorted order, the last fastest.
        assert_eq!(ranges, [0.1, 0.2, 0.3, 0.1, 0.2, 0.3]);
        assert_eq!(
            points[3].overrides["odometry"]["linear_std"].as_float(),
            Some(0.03)
        );
        assert!(points[0].overrides["sighting"]["mount"].is_array());
        assert_eq!(
            points[5].label,
            [
                ("odometry.linear_std".to_owned(), "0.03".to_owned()),
                ("sighting.range_std".to_owned(), "0.3".to_owned()),
            ]
        );
        // A list of lists varies a list-valued setting.
        let grid = table("[sighting]\nmount = [[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]]\n");
        assert_eq!(expand(&grid, &base).len(), 2);
    }

    #[test]
    fn runs_parse_ranges_and_refuse_bad_robots() {
        let runs = parse_runs(&["mrclam:dataset6/robot2-4".into(), "mrclam:d1".into()]).unwrap();
        let robots: Vec<u8> = runs.iter().map(|r| r.robot).collect();
        assert_eq!(robots, [2, 3, 4, 1]);
        assert_eq!(runs[0].dataset, DatasetSpec::Mrclam("dataset6".into()));
        let err = parse_runs(&["mrclam:dataset6/robot9".into()]).unwrap_err();
        assert!(err.to_string().contains("robot1 … robot5"), "{err}");
        assert!(parse_runs(&["mrclam:dataset6/robot4-2".into()]).is_err());
        assert!(parse_runs(&["carmen:x.clf".into()]).is_err());
        // Stress variants follow each robot of a range.
        let runs = parse_runs(&["mrclam:dataset6/robot2-3+8hz+turn1.4".into()]).unwrap();
        let specs: Vec<&DatasetSpec> = runs.iter().map(|r| &r.dataset).collect();
        let stressed = DatasetSpec::Mrclam("dataset6+8hz+turn1.4".into());
        assert_eq!(specs, [&stressed, &stressed]);
        assert_eq!(runs[1].robot, 3);
        assert!(parse_runs(&["mrclam:dataset6/robot2+slow".into()]).is_err());
    }

    #[test]
    fn aggregates_are_mean_and_worst_per_point() {
        let row = |settings, ate, nees| Row {
            settings,
            label: format!("p{settings}"),
            recording: "r".into(),
            ate_se2_m: Some(ate),
            landmark_se2_m: None,
            nees_mean: Some(nees),
            nees_in_95: None,
            nis_mean: None,
            purity: Some(1.0),
            dead_reckoning_se2_m: None,
            recoveries: 0,
            landmarks_created: 15,
            lost_share: 0.0,
            lost_flag_agreement: None,
        };
        let rows = [row(0, 0.4, 5.0), row(0, 0.2, 9.0), row(1, 0.1, 2.0)];
        let a = aggregate(&rows);
        assert_eq!(a[0].settings, 1, "best mean first");
        assert!((a[1].ate_mean_m - 0.3).abs() < 1e-12);
        assert_eq!(
            (a[1].ate_worst_m, a[1].nees_worst, a[1].runs),
            (0.4, 9.0, 2)
        );
    }
}
