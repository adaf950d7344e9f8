//! Structure-aware fuzzing of the readers from the command line (issue 62): inputs that
//! are well formed but wrong in one place — a count off by one, a NaN or an absurd value
//! in one field, two records swapped (stamps going back), one scan shorter than the
//! others, a field dropped, the file cut short, a map header that disagrees with its
//! pixels. For every reader the property is the same:
//!
//! - `host-sim` never panics (exit code 101);
//! - when it exits 0, every figure it wrote is finite (`metrics.json` has no `null`,
//!   `trajectory.tum` no NaN) and every record of the input is accounted for (a grid
//!   run's `input_loss` counts every front scan; a landmark run's `inputs` every motion
//!   record and sighting, `read` = `used` + what was lost);
//! - when it fails, the error names the file at fault.
//!
//! Proptest draws the mutations from a fixed seed (`PROPTEST_RNG_SEED` in the test
//! configuration below), so a run is reproducible; a failing case is printed whole, and
//! kept inputs of the readers' byte fuzzers live in `fuzz/regressions/`.

#[path = "common/cases.rs"]
mod cases;
mod common;

use cases::run_cases;
use common::{host_sim, succeeds};
use proptest::prelude::*;
use std::path::Path;

/// One way of making a well-formed input wrong.
#[derive(Clone, Debug)]
enum Mutation {
    /// The integer second field of a line (a CARMEN beam count, a record's stamp in a
    /// plain log) off by `delta`.
    CountOff { line: usize, delta: i64 },
    /// One numeric field replaced by `value` (`nan`, `inf`, `-1e30`, `1e30`, `-1`, `0`).
    Value {
        line: usize,
        field: usize,
        value: &'static str,
    },
    /// Two lines swapped (their stamps now go back).
    Swap { a: usize, b: usize },
    /// A CARMEN scan one reading shorter than the others, its count kept consistent.
    ShorterScan { line: usize },
    /// One field removed (every later field shifts).
    DropField { line: usize, field: usize },
    /// The file cut at a byte.
    Truncate { at: usize },
    /// A line repeated.
    Repeat { line: usize },
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let index = 0usize..64;
    let values = prop::sample::select(vec!["nan", "inf", "-inf", "1e30", "-1e30", "-1", "0"]);
    prop_oneof![
        (index.clone(), prop::sample::select(vec![-1i64, 1]))
            .prop_map(|(line, delta)| Mutation::CountOff { line, delta }),
        (index.clone(), 0usize..400, values).prop_map(|(line, field, value)| Mutation::Value {
            line,
            field,
            value
        }),
        (index.clone(), index.clone()).prop_map(|(a, b)| Mutation::Swap { a, b }),
        index
            .clone()
            .prop_map(|line| Mutation::ShorterScan { line }),
        (index.clone(), 0usize..400).prop_map(|(line, field)| Mutation::DropField { line, field }),
        (0usize..1 << 16).prop_map(|at| Mutation::Truncate { at }),
        index.prop_map(|line| Mutation::Repeat { line }),
    ]
}

/// `text` with `m` applied (indices taken modulo what the text has; a mutation that
/// finds nothing to change leaves the text as it was).
fn apply(text: &str, m: &Mutation) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let n = lines.len().max(1);
    let fields_of = |l: &str| -> Vec<String> { l.split_whitespace().map(str::to_owned).collect() };
    match *m {
        Mutation::CountOff { line, delta } => {
            let mut f = fields_of(&lines[line % n]);
            if let Some(v) = f.get(1).and_then(|s| s.parse::<i64>().ok()) {
                f[1] = (v + delta).to_string();
                lines[line % n] = f.join(" ");
            }
        }
        Mutation::Value { line, field, value } => {
            let mut f = fields_of(&lines[line % n]);
            let numeric: Vec<usize> = (0..f.len())
                .filter(|&i| f[i].parse::<f64>().is_ok())
                .collect();
            if !numeric.is_empty() {
                f[numeric[field % numeric.len()]] = value.to_owned();
                lines[line % n] = f.join(" ");
            }
        }
        Mutation::Swap { a, b } => lines.swap(a % n, b % n),
        Mutation::ShorterScan { line } => {
            let mut f = fields_of(&lines[line % n]);
            if f.first().is_some_and(|t| t == "FLASER")
                && let Some(count) = f.get(1).and_then(|s| s.parse::<usize>().ok())
                && count > 1
            {
                f[1] = (count - 1).to_string();
                f.remove(2);
                lines[line % n] = f.join(" ");
            }
        }
        Mutation::DropField { line, field } => {
            let mut f = fields_of(&lines[line % n]);
            if !f.is_empty() {
                let at = field % f.len();
                f.remove(at);
                lines[line % n] = f.join(" ");
            }
        }
        Mutation::Truncate { at } => {
            let joined = lines.join("\n") + "\n";
            let mut cut = at % joined.len().max(1);
            while !joined.is_char_boundary(cut) {
                cut -= 1;
            }
            return joined[..cut].to_owned();
        }
        Mutation::Repeat { line } => {
            let l = lines[line % n].clone();
            lines.insert(line % n, l);
        }
    }
    lines.join("\n") + "\n"
}

/// What a run left: its exit code, standard error and output folder.
struct Run {
    code: Option<i32>,
    stderr: String,
}

fn run(args: &[&str], out: &Path) -> Run {
    let o = host_sim()
        .args(args)
        .args(["--quiet", "--no-plots", "--out"])
        .arg(out)
        .output()
        .expect("host-sim starts");
    Run {
        code: o.status.code(),
        stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
    }
}

/// A grid-SLAM replay of `dataset` with 8 particles and the `extra` arguments.
fn grid_replay(dataset: &str, extra: &[&str], out: &Path) -> Run {
    let mut args = vec![
        "replay",
        "--filter",
        "grid-slam",
        "--particles",
        "8",
        "--dataset",
        dataset,
    ];
    args.extend_from_slice(extra);
    run(&args, out)
}

/// The property every reader keeps; `accounted` checks the counts of a run that
/// succeeded against the input's text.
fn holds(
    r: &Run,
    out: &Path,
    text: &str,
    names: &[&str],
    accounted: impl Fn(&serde_json::Value, &str) -> Result<(), String>,
) -> Result<Option<i32>, TestCaseError> {
    prop_assert_ne!(r.code, Some(101), "host-sim panicked: {}", r.stderr);
    if r.code == Some(0) {
        let json = std::fs::read_to_string(out.join("metrics.json"))
            .map_err(|e| TestCaseError::fail(format!("exit 0 without metrics.json: {e}")))?;
        prop_assert!(!json.contains("null"), "a null figure after exit 0: {json}");
        let metrics: serde_json::Value = serde_json::from_str(&json).unwrap();
        if let Ok(tum) = std::fs::read_to_string(out.join("trajectory.tum")) {
            prop_assert!(
                tum.lines()
                    .filter(|l| !l.starts_with('#'))
                    .flat_map(str::split_whitespace)
                    .all(|v| v.parse::<f64>().is_ok_and(f64::is_finite)),
                "a non-finite value in trajectory.tum"
            );
        }
        accounted(&metrics, text).map_err(TestCaseError::fail)?;
    } else {
        prop_assert!(
            names.iter().any(|n| r.stderr.contains(n)),
            "the error names none of {names:?}: {}",
            r.stderr
        );
    }
    Ok(r.code)
}

/// A CARMEN log of 12 front scans of 30 beams (2 m, one wall at 1 m), the robot moving 3 cm
/// a scan; a parameter line and an odometry line among them.
fn carmen_log() -> String {
    let mut text = String::from("PARAM robot_front_laser_max 81.9\n");
    for i in 0..12 {
        let t = 100.0 + 0.1 * i as f64;
        let x = 0.03 * i as f64;
        let beams: Vec<String> = (0..30)
            .map(|b| {
                if b < 10 {
                    "1.0".into()
                } else {
                    format!("{:.2}", 2.0 + 0.01 * b as f64)
                }
            })
            .collect();
        text += &format!(
            "FLASER 30 {} {x:.3} 0 0 {x:.3} 0 0 {t:.3} host {t:.3}\n",
            beams.join(" ")
        );
        if i == 5 {
            text += &format!("ODOM {x:.3} 0 0 0.3 0 0 {t:.3} host {t:.3}\n");
        }
    }
    text
}

/// Scans a grid run counted: read, and used + skipped = read.
fn scans_accounted(metrics: &serde_json::Value, text: &str) -> Result<(), String> {
    let front = text.lines().filter(|l| l.starts_with("FLASER ")).count() as u64;
    let scans = &metrics["input_loss"]["scans"];
    let (read, used, skipped) = (
        scans["read"].as_u64(),
        scans["used"].as_u64(),
        scans["skipped"].as_u64(),
    );
    if read != Some(front) || used.zip(skipped).map(|(u, s)| u + s) != read {
        return Err(format!(
            "{front} front scans in the log, but input_loss.scans is {scans}"
        ));
    }
    Ok(())
}

#[test]
fn a_mutated_carmen_log_fails_naming_it_or_is_used_whole() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log.clf");
    let base = carmen_log();
    let dataset = format!("carmen:{}", log.display());
    run_cases(256, &mutation(), |m| {
        let text = apply(&base, &m);
        std::fs::write(&log, &text).unwrap();
        let out = dir.path().join("out");
        let r = grid_replay(&dataset, &[], &out);
        holds(&r, &out, &text, &["log.clf"], scans_accounted)
    });
}

/// A room map (map.yaml + map.pgm): 60 × 60 cells of 5 cm, walls around free space.
fn write_map(dir: &Path, yaml: &str, pgm_header: &str) {
    let mut pgm = pgm_header.as_bytes().to_vec();
    for y in 0..60 {
        for x in 0..60 {
            let wall = x == 0 || y == 0 || x == 59 || y == 59;
            pgm.push(if wall { 0 } else { 254 });
        }
    }
    std::fs::write(dir.join("map.pgm"), pgm).unwrap();
    std::fs::write(dir.join("map.yaml"), yaml).unwrap();
}

const MAP_YAML: &str = "image: map.pgm\nresolution: 0.05\norigin: [-1.5, -1.5, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n";

#[test]
fn a_mutated_map_fails_naming_it_or_localizes_the_whole_log() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log.clf");
    std::fs::write(&log, carmen_log()).unwrap();
    let dataset = format!("carmen:{}", log.display());
    let map = dir.path().join("map.yaml");
    let header = "P5\n60 60\n255\n";
    // The mutations of the yaml's values and lines, and of the PGM's header.
    let yaml_or_header = prop_oneof![
        mutation().prop_map(|m| (apply(MAP_YAML, &m), header.to_owned())),
        mutation().prop_map(move |m| (MAP_YAML.to_owned(), apply(header, &m))),
    ];
    run_cases(192, &yaml_or_header, |(yaml, pgm_header)| {
        write_map(dir.path(), &yaml, &pgm_header);
        let out = dir.path().join("out");
        let r = run(
            &[
                "localize",
                "--map",
                map.to_str().unwrap(),
                "--particles",
                "8",
                "--dataset",
                &dataset,
            ],
            &out,
        );
        holds(
            &r,
            &out,
            &carmen_log(),
            &["map.yaml", "map.pgm"],
            scans_accounted,
        )
    });
}

/// A plain landmark log: a robot driving past three posts, with ground truth.
const LANDMARK_LOG: &str = "velocity 0.0 0.5 0.0\n\
    truth 0.0 0 0 0\n\
    sighting 0.0 3.0 0.2 1\n\
    sighting 0.0 4.0 -0.3 2\n\
    velocity 1.0 0.5 0.05\n\
    truth 1.0 0.5 0 0\n\
    sighting 1.0 2.5 0.25 1\n\
    sighting 1.0 3.6 -0.35 2\n\
    sighting 1.0 5.0 0.6 3\n\
    velocity 2.0 0.5 0.05\n\
    truth 2.0 1.0 0.02 0.05\n\
    sighting 2.0 2.0 0.3 1\n\
    sighting 2.0 4.6 0.7 3\n\
    velocity 3.0 0.0 0.0\n\
    truth 3.0 1.5 0.06 0.1\n\
    landmark 1 2.9 0.6\n\
    landmark 2 3.8 -1.2\n\
    landmark 3 4.0 2.8\n";

/// Every motion record and sighting of a landmark run counted.
fn records_accounted(metrics: &serde_json::Value, text: &str) -> Result<(), String> {
    let count = |kinds: &[&str]| {
        text.lines()
            .filter(|l| {
                l.split_whitespace()
                    .next()
                    .is_some_and(|k| kinds.contains(&k))
            })
            .count() as u64
    };
    let inputs = &metrics["inputs"];
    let o = &inputs["odometry"];
    let s = &inputs["sightings"];
    let sum = |v: &serde_json::Value, keys: &[&str]| {
        keys.iter().filter_map(|k| v[k].as_u64()).sum::<u64>()
    };
    let fine = o["read"].as_u64() == Some(count(&["velocity", "increment", "ackermann"]))
        && s["read"].as_u64() == Some(count(&["sighting"]))
        && sum(o, &["used", "refused_implausible", "refused_by_filter"])
            >= o["read"].as_u64().unwrap_or(u64::MAX)
        && sum(
            s,
            &[
                "used",
                "reader_dropped",
                "out_of_range",
                "gated",
                "ambiguous",
                "refused",
            ],
        ) == s["read"].as_u64().unwrap_or(u64::MAX);
    if fine {
        Ok(())
    } else {
        Err(format!(
            "the log's records are not all accounted for: {inputs}"
        ))
    }
}

#[test]
fn a_mutated_landmark_log_fails_naming_it_or_is_used_whole() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("run.txt");
    let dataset = format!("landmarks:{}", log.display());
    run_cases(256, &mutation(), |m| {
        let text = apply(LANDMARK_LOG, &m);
        std::fs::write(&log, &text).unwrap();
        let out = dir.path().join("out");
        let r = run(&["replay", "--dataset", &dataset], &out);
        holds(&r, &out, &text, &["run.txt"], records_accounted)
    });
}

/// A one-robot MRCLAM folder: the header lines MRCLAM's files start with, then rows.
const MRCLAM_HEAD: &str = "# a\n# b\n# c\n# d\n";

/// The files of a small MRCLAM folder: the robot drives 3 s past two landmarks.
fn mrclam_files() -> Vec<(&'static str, String)> {
    let mut odometry = String::new();
    let mut truth = String::new();
    for i in 0..30 {
        let t = 10.0 + 0.1 * f64::from(i);
        odometry += &format!("{t:.2}\t0.2\t0.05\n");
        truth += &format!(
            "{t:.2}\t{:.3}\t0.0\t{:.3}\n",
            0.02 * f64::from(i),
            0.005 * f64::from(i)
        );
    }
    let mut sightings = String::new();
    for i in 0..10 {
        let t = 10.05 + 0.3 * f64::from(i);
        sightings += &format!(
            "{t:.2}\t72\t{:.2}\t0.3\n{t:.2}\t18\t{:.2}\t-0.4\n",
            3.0 - 0.05 * f64::from(i),
            4.0 - 0.05 * f64::from(i)
        );
    }
    vec![
        ("Barcodes.dat", "6\t72\n7\t18\n".to_owned()),
        ("Robot1_Odometry.dat", odometry),
        ("Robot1_Measurement.dat", sightings),
        ("Robot1_Groundtruth.dat", truth),
        (
            "Landmark_Groundtruth.dat",
            "6\t3.3\t1.0\t0.01\t0.01\n7\t3.8\t-1.7\t0.01\t0.01\n".to_owned(),
        ),
    ]
}

#[test]
fn a_mutated_mrclam_folder_fails_naming_the_file_or_is_used_whole() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("run");
    std::fs::create_dir_all(&folder).unwrap();
    let dataset = format!("mrclam:{}", folder.display());
    let files = mrclam_files();
    let names: Vec<&str> = files.iter().map(|(n, _)| *n).collect();
    // One of the five files mutated.
    let strategy = (0..files.len(), mutation());
    run_cases(192, &strategy, |(which, m)| {
        let mut rows = [0usize; 2];
        for (i, (name, body)) in files.iter().enumerate() {
            let body = if i == which {
                apply(body, &m)
            } else {
                body.clone()
            };
            if *name == "Robot1_Odometry.dat" {
                rows[0] = body.lines().count();
            } else if *name == "Robot1_Measurement.dat" {
                rows[1] = body.lines().count();
            }
            std::fs::write(folder.join(name), format!("{MRCLAM_HEAD}{body}")).unwrap();
        }
        let out = dir.path().join("out");
        let r = run(&["replay", "--robot", "1", "--dataset", &dataset], &out);
        holds(&r, &out, "", &names, |metrics, _| {
            let inputs = &metrics["inputs"];
            let odometry = inputs["odometry"]["read"].as_u64();
            let sightings = inputs["sightings"]["read"].as_u64();
            if odometry == Some(rows[0] as u64) && sightings == Some(rows[1] as u64) {
                Ok(())
            } else {
                Err(format!(
                    "{rows:?} odometry and measurement rows, but {inputs}"
                ))
            }
        })
    });
}

/// A grid settings file setting most keys (the values `microcontroller` has), with loop
/// closure.
const GRID_SETTINGS: &str = "base = \"microcontroller\"\n\
    resolution = 0.05\n\
    hit = 4\n\
    miss = 1\n\
    range_weight_exponent = 0.0\n\
    resample_neff_fraction = 0.5\n\
    seed = 3\n\
    shift_window_cells = 4\n\
    beam_decimation = 2\n\
    distance_std = 0.01\n\
    heading_std_per_radian = 0.1\n\
    loss_warning_fraction = 0.2\n\
    [loop_closure]\n\
    keyframe_distance_m = 0.1\n\
    candidate_radius_m = 3.0\n\
    min_hit_fraction = 0.5\n";

#[test]
fn a_mutated_grid_settings_file_fails_naming_it_or_is_used() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log.clf");
    std::fs::write(&log, carmen_log()).unwrap();
    let dataset = format!("carmen:{}", log.display());
    let config = dir.path().join("grid.toml");
    run_cases(128, &mutation(), |m| {
        std::fs::write(&config, apply(GRID_SETTINGS, &m)).unwrap();
        let out = dir.path().join("out");
        let r = grid_replay(&dataset, &["--config", config.to_str().unwrap()], &out);
        holds(&r, &out, &carmen_log(), &["grid.toml"], scans_accounted)
    });
}

#[test]
fn a_mutated_landmark_settings_file_fails_naming_it_or_is_used() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("run.txt");
    std::fs::write(&log, LANDMARK_LOG).unwrap();
    let dataset = format!("landmarks:{}", log.display());
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/landmarks.toml");
    let base = std::fs::read_to_string(shipped).unwrap();
    let config = dir.path().join("settings.toml");
    run_cases(128, &mutation(), |m| {
        std::fs::write(&config, apply(&base, &m)).unwrap();
        let out = dir.path().join("out");
        let r = run(
            &[
                "replay",
                "--config",
                config.to_str().unwrap(),
                "--dataset",
                &dataset,
            ],
            &out,
        );
        holds(
            &r,
            &out,
            LANDMARK_LOG,
            &["settings.toml"],
            records_accounted,
        )
    });
}

#[test]
fn the_unmutated_inputs_are_used_whole() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log.clf");
    std::fs::write(&log, carmen_log()).unwrap();
    let out = dir.path().join("grid");
    succeeds(
        host_sim()
            .args([
                "replay",
                "--quiet",
                "--no-plots",
                "--particles",
                "8",
                "--dataset",
            ])
            .arg(format!("carmen:{}", log.display()))
            .arg("--out")
            .arg(&out),
    );
    let metrics = std::fs::read_to_string(out.join("metrics.json")).unwrap();
    scans_accounted(&serde_json::from_str(&metrics).unwrap(), &carmen_log()).unwrap();
    let run = dir.path().join("run.txt");
    std::fs::write(&run, LANDMARK_LOG).unwrap();
    let out = dir.path().join("landmarks");
    succeeds(
        host_sim()
            .args(["replay", "--quiet", "--no-plots", "--dataset"])
            .arg(format!("landmarks:{}", run.display()))
            .arg("--out")
            .arg(&out),
    );
    let metrics = std::fs::read_to_string(out.join("metrics.json")).unwrap();
    records_accounted(&serde_json::from_str(&metrics).unwrap(), LANDMARK_LOG).unwrap();
}

#[test]
fn the_mutations_change_what_they_say() {
    let log = carmen_log();
    let first_scan = |t: &str| t.lines().nth(1).unwrap().to_owned();
    let off = apply(&log, &Mutation::CountOff { line: 1, delta: 1 });
    assert!(first_scan(&off).starts_with("FLASER 31 "));
    let shorter = apply(&log, &Mutation::ShorterScan { line: 1 });
    assert_eq!(
        first_scan(&shorter).split_whitespace().count(),
        first_scan(&log).split_whitespace().count() - 1
    );
    let nan = apply(
        "a 1 2\n",
        &Mutation::Value {
            line: 0,
            field: 1,
            value: "nan",
        },
    );
    assert_eq!(nan, "a 1 nan\n");
    let swapped = apply("a\nb\n", &Mutation::Swap { a: 0, b: 1 });
    assert_eq!(swapped, "b\na\n");
    assert_eq!(apply("abc\n", &Mutation::Truncate { at: 2 }), "ab");
}
