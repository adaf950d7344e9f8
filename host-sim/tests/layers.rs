//! The layers of host-sim: every file imports only its own layer and the layers below it,
//! and no two modules import each other, directly or around a loop.
//!
//! Reads every `.rs` file under `src/`, takes each `crate::…` and `super::…` path outside
//! comments, and checks it against the layer order below. Child modules named without a
//! prefix (`mod x; use x::…`) are inside their parent and need no check.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The layers, bottom first: the first folder (or file) under `src/` names the layer.
/// A module may import from its own layer and from any layer before it in this list.
const LAYERS: &[&str] = &[
    "domain",   // settings and plain domain types
    "inputs",   // readers, simulator worlds, fault injection, camera world
    "drivers",  // the EKF and grid run drivers, the camera chains
    "metrics",  // scores against ground truth
    "output",   // TUM, metrics.json, map_server maps, PNG
    "commands", // one module per subcommand
    "cli",      // clap only
];

/// Files that only declare the layers and start the program.
const ROOTS: &[&str] = &["lib", "main"];

/// Module path of a source file: `src/inputs/readers/mod.rs` → `inputs::readers`.
fn module_path(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).expect("file under src");
    let mut parts: Vec<String> = rel
        .iter()
        .map(|c| c.to_string_lossy().trim_end_matches(".rs").to_owned())
        .collect();
    if parts.last().is_some_and(|p| p == "mod") {
        parts.pop();
    }
    parts
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("read src") {
        let path = entry.expect("dir entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The source without `//` comments (doc links are not imports) and string literals.
fn code_only(text: &str) -> String {
    let mut out = String::new();
    for line in text.lines() {
        let mut in_str = false;
        let mut prev = ' ';
        let mut kept = String::new();
        let mut chars = line.chars().peekable();
        while let Some(c) = chars.next() {
            if !in_str && c == '/' && chars.peek() == Some(&'/') {
                break;
            }
            if c == '"' && prev != '\\' {
                in_str = !in_str;
            } else if !in_str {
                kept.push(c);
            }
            prev = c;
        }
        out.push_str(&kept);
        out.push('\n');
    }
    out
}

/// Every path `crate::a::b…` or `super::…` in `code`, resolved to an absolute module path
/// (as far as it names modules; `{…}` groups expanded one level).
fn imported_paths(code: &str, module: &[String]) -> Vec<Vec<String>> {
    let mut found = Vec::new();
    for (prefix, base) in [
        ("crate::", Vec::new()),
        ("super::", module[..module.len().saturating_sub(1)].to_vec()),
    ] {
        let mut rest = code;
        while let Some(i) = rest.find(prefix) {
            let before = rest[..i].chars().next_back();
            rest = &rest[i + prefix.len()..];
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
                continue; // `super::super::` is handled by the first `super::`; `x::crate` is no path
            }
            let mut path = base.clone();
            let mut tail = rest;
            let mut ups = 0;
            while let Some(t) = tail.strip_prefix("super::") {
                ups += 1;
                tail = t;
            }
            for _ in 0..ups {
                path.pop();
            }
            let segs: Vec<&str> = tail
                .split("::")
                .map(|s| {
                    s.split(|c: char| !(c.is_alphanumeric() || c == '_'))
                        .next()
                        .unwrap_or("")
                })
                .take_while(|s| !s.is_empty())
                .collect();
            if tail.starts_with('*') && prefix == "super::" {
                continue; // `use super::*` in a test module: the file itself
            }
            path.extend(segs.iter().map(|s| s.to_string()));
            // `crate::{a, b}` / `super::{a::x, b}`: one path per group member.
            let after: String = segs.iter().map(|s| format!("{s}::")).collect();
            match tail
                .strip_prefix(after.as_str())
                .filter(|g| g.starts_with('{'))
            {
                Some(g) => {
                    let mut depth = 0;
                    let mut member = String::new();
                    let mut members = Vec::new();
                    for c in g.chars() {
                        match c {
                            '{' => depth += 1,
                            '}' => depth -= 1,
                            _ => {}
                        }
                        if depth == 0 {
                            break;
                        }
                        if depth == 1 && c == ',' {
                            members.push(std::mem::take(&mut member));
                        } else if !(depth == 1 && c == '{') {
                            member.push(c);
                        }
                    }
                    members.push(member);
                    for m in members {
                        let name = m.trim().split("::").next().unwrap_or("").trim().to_owned();
                        let mut p = path.clone();
                        if name != "self" && !name.is_empty() {
                            p.push(name);
                        }
                        if !m.trim().is_empty() {
                            found.push(p);
                        }
                    }
                }
                None => found.push(path),
            }
        }
    }
    found
}

struct Crate {
    /// Module path → its imports.
    imports: BTreeMap<Vec<String>, Vec<Vec<String>>>,
}

fn read_crate(src: &Path) -> Crate {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    assert!(files.len() > 20, "host-sim/src has its modules");
    let mut imports = BTreeMap::new();
    for file in files {
        let text = std::fs::read_to_string(&file).expect("read source");
        let module = module_path(src, &file);
        imports.insert(module.clone(), imported_paths(&code_only(&text), &module));
    }
    Crate { imports }
}

fn layer_of(module: &[String]) -> Option<usize> {
    let top = module.first()?;
    LAYERS.iter().position(|l| l == top)
}

/// The upward imports: `(file's module, imported path)`.
fn upward_imports(krate: &Crate) -> Vec<String> {
    let mut bad = Vec::new();
    for (module, paths) in &krate.imports {
        if module.len() == 1 && ROOTS.contains(&module[0].as_str()) {
            continue;
        }
        let own = layer_of(module)
            .unwrap_or_else(|| panic!("{} is in no layer of LAYERS", module.join("::")));
        for path in paths {
            match layer_of(path) {
                Some(l) if l <= own => {}
                Some(l) => bad.push(format!(
                    "{} (layer {}) imports {} (layer {})",
                    module.join("::"),
                    LAYERS[own],
                    path.join("::"),
                    LAYERS[l]
                )),
                None => bad.push(format!(
                    "{} imports {}, which is in no layer",
                    module.join("::"),
                    path.join("::")
                )),
            }
        }
    }
    bad
}

/// A module's unit for the cycle check: its first two path segments (`inputs::readers`),
/// so that a folder's files and the folder count as one.
fn unit(path: &[String], units: &BTreeSet<Vec<String>>) -> Vec<String> {
    (1..=path.len().min(2))
        .rev()
        .map(|n| path[..n].to_vec())
        .find(|p| units.contains(p))
        .unwrap_or_else(|| path[..1.min(path.len())].to_vec())
}

/// A loop of imports between units, if there is one.
fn find_cycle(krate: &Crate) -> Option<Vec<String>> {
    let units: BTreeSet<Vec<String>> = krate
        .imports
        .keys()
        .map(|m| m[..m.len().min(2)].to_vec())
        .collect();
    let mut edges: BTreeMap<Vec<String>, BTreeSet<Vec<String>>> = BTreeMap::new();
    for (module, paths) in &krate.imports {
        let from = unit(module, &units);
        for p in paths {
            let to = unit(p, &units);
            if to != from {
                edges.entry(from.clone()).or_default().insert(to);
            }
        }
    }
    // Depth-first search, colouring nodes: 1 on the stack, 2 done.
    fn visit(
        n: &Vec<String>,
        edges: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
        colour: &mut BTreeMap<Vec<String>, u8>,
        stack: &mut Vec<Vec<String>>,
    ) -> Option<Vec<String>> {
        colour.insert(n.clone(), 1);
        stack.push(n.clone());
        for m in edges.get(n).into_iter().flatten() {
            match colour.get(m).copied().unwrap_or(0) {
                1 => {
                    let start = stack.iter().position(|s| s == m).unwrap_or(0);
                    let mut cycle: Vec<String> =
                        stack[start..].iter().map(|s| s.join("::")).collect();
                    cycle.push(m.join("::"));
                    return Some(cycle);
                }
                0 => {
                    if let Some(c) = visit(m, edges, colour, stack) {
                        return Some(c);
                    }
                }
                _ => {}
            }
        }
        stack.pop();
        colour.insert(n.clone(), 2);
        None
    }
    let mut colour = BTreeMap::new();
    for u in &units {
        if colour.get(u).copied().unwrap_or(0) == 0
            && let Some(c) = visit(u, &edges, &mut colour, &mut Vec::new())
        {
            return Some(c);
        }
    }
    None
}

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

#[test]
fn every_file_imports_only_its_own_or_lower_layers() {
    let krate = read_crate(&src());
    let bad = upward_imports(&krate);
    assert!(bad.is_empty(), "upward imports:\n{}", bad.join("\n"));
}

#[test]
fn no_import_cycle_between_modules() {
    let krate = read_crate(&src());
    assert_eq!(find_cycle(&krate), None);
}

#[test]
fn the_checks_see_an_upward_import_and_a_cycle() {
    // The checker itself on planted sources: an EKF driver importing the command line,
    // and two readers importing each other.
    let mut krate = read_crate(&src());
    let ekf = vec!["drivers".to_owned(), "ekf".to_owned()];
    let code = code_only("use crate::cli::Cli; // crate::commands in a comment is ignored\n");
    krate
        .imports
        .insert(ekf.clone(), imported_paths(&code, &ekf));
    let bad = upward_imports(&krate);
    assert_eq!(
        bad,
        ["drivers::ekf (layer drivers) imports cli::Cli (layer cli)"]
    );

    let mut krate = read_crate(&src());
    let a = vec!["inputs".to_owned(), "faults".to_owned()];
    let b = vec![
        "inputs".to_owned(),
        "readers".to_owned(),
        "carmen".to_owned(),
    ];
    krate.imports.insert(
        a.clone(),
        imported_paths("use crate::inputs::readers::carmen::X;", &a),
    );
    krate.imports.insert(
        b.clone(),
        imported_paths("use crate::inputs::{faults, sim};", &b),
    );
    let cycle = find_cycle(&krate).expect("the planted loop is found");
    assert!(
        cycle.contains(&"inputs::faults".to_owned())
            && cycle.contains(&"inputs::readers".to_owned()),
        "{cycle:?}"
    );
}

#[test]
fn paths_are_resolved_from_the_file() {
    let m = vec![
        "inputs".to_owned(),
        "readers".to_owned(),
        "mrclam".to_owned(),
    ];
    assert_eq!(
        imported_paths("use super::text::{ReadError, invalid};", &m),
        [
            vec!["inputs", "readers", "text", "ReadError"],
            vec!["inputs", "readers", "text", "invalid"]
        ]
    );
    assert_eq!(
        imported_paths(
            "use crate::domain::{AssociationMode, recording::{Recording, TruePose}, grid};",
            &m
        ),
        [
            vec!["domain", "AssociationMode"],
            vec!["domain", "recording"],
            vec!["domain", "grid"]
        ]
    );
    assert!(imported_paths(&code_only("let s = \"crate::cli\"; // crate::cli\n"), &m).is_empty());
}

/// The longest a source file of `core/src` or `host-sim/src` may be, in lines: a file
/// holds one concern, and a module's tests live in a file of their own
/// (`x.rs` declares `#[cfg(test)] mod tests;`, the tests are in `x/tests.rs`), which
/// this limit leaves out.
const MAX_FILE_LINES: usize = 800;

/// Files of `dirs` longer than [`MAX_FILE_LINES`], test files (`tests.rs`,
/// `*_tests.rs`, anything under a `tests/` folder) left out.
fn long_files(dirs: &[PathBuf]) -> Vec<String> {
    let mut files = Vec::new();
    for dir in dirs {
        rust_files(dir, &mut files);
    }
    files
        .iter()
        .filter(|f| {
            let name = f.file_stem().map(|s| s.to_string_lossy().into_owned());
            let is_test = name.is_some_and(|n| n == "tests" || n.ends_with("_tests"))
                || f.components().any(|c| c.as_os_str() == "tests");
            !is_test
        })
        .filter_map(|f| {
            let lines = std::fs::read_to_string(f)
                .expect("read source")
                .lines()
                .count();
            (lines > MAX_FILE_LINES).then(|| format!("{}: {lines} lines", f.display()))
        })
        .collect()
}

#[test]
fn no_source_file_is_longer_than_the_limit() {
    let core = Path::new(env!("CARGO_MANIFEST_DIR")).join("../core/src");
    let long = long_files(&[src(), core]);
    assert!(
        long.is_empty(),
        "files over {MAX_FILE_LINES} lines (split them by concern; tests go in a file of \
         their own): {long:#?}"
    );
}

#[test]
fn the_length_check_sees_a_long_file_and_leaves_tests_out() {
    let dir = std::env::temp_dir().join(format!("microslam-long-files-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("module")).expect("temp dir");
    let long = "fn f() {}\n".repeat(MAX_FILE_LINES + 1);
    std::fs::write(dir.join("module.rs"), &long).expect("write");
    std::fs::write(dir.join("module/tests.rs"), &long).expect("write");
    std::fs::write(dir.join("short.rs"), "fn g() {}\n".repeat(MAX_FILE_LINES)).expect("write");
    let found = long_files(std::slice::from_ref(&dir));
    std::fs::remove_dir_all(&dir).expect("clean up");
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(found[0].contains("module.rs: 801 lines"), "{found:?}");
}

/// The library's levels (`core/src`, docs/design.md), bottom first: a module imports only
/// modules on lower levels. `testing` (the unit tests' worlds, compiled for tests only)
/// and the unit tests themselves are left out: a test may drive any layer.
const CORE_LEVELS: &[&[&str]] = &[
    &["scalar", "log", "checksum"],
    &["geometry", "gate", "error"],
    &["sensors"],
    &["motion", "event"],
    &["ekf", "grid"],
    &["association", "pf"],
    &["feed", "wire", "slam"],
    &["device"],
    &["profile"],
];

fn core_level(top: &str) -> Option<usize> {
    CORE_LEVELS.iter().position(|level| level.contains(&top))
}

fn is_test_module(module: &[String]) -> bool {
    module
        .iter()
        .any(|m| m == "tests" || m.ends_with("_tests") || m == "testing")
}

/// Imports of the library that do not go to a lower level: `(module, path)` as text.
fn core_level_breaches(krate: &Crate) -> Vec<String> {
    let mut bad = Vec::new();
    for (module, paths) in &krate.imports {
        if module.len() == 1 && ROOTS.contains(&module[0].as_str()) || is_test_module(module) {
            continue;
        }
        let own = core_level(&module[0])
            .unwrap_or_else(|| panic!("core module {} is on no level", module.join("::")));
        for path in paths {
            let Some(top) = path.first() else { continue };
            if top == &module[0] || top == "testing" {
                continue;
            }
            // A path that starts with no module of the library is an item of the crate
            // root or a `super::` path inside one module: nothing to check.
            match core_level(top) {
                None => {}
                Some(l) if l < own => {}
                Some(_) => bad.push(format!(
                    "{} (level {own}) imports {}",
                    module.join("::"),
                    path.join("::")
                )),
            }
        }
    }
    bad
}

fn core_src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../core/src")
}

#[test]
fn every_core_module_imports_only_lower_levels() {
    let krate = read_crate(&core_src());
    let bad = core_level_breaches(&krate);
    assert!(
        bad.is_empty(),
        "imports that are not downward:\n{}",
        bad.join("\n")
    );
}

#[test]
fn the_core_check_sees_a_sideways_and_an_upward_import() {
    let mut krate = read_crate(&core_src());
    // `grid` importing `ekf` (the same level) and `scalar` importing `geometry` (a level up).
    krate
        .imports
        .entry(vec!["grid".to_owned(), "view".to_owned()])
        .or_default()
        .push(vec!["ekf".to_owned(), "EkfSlam".to_owned()]);
    krate
        .imports
        .entry(vec!["scalar".to_owned()])
        .or_default()
        .push(vec!["geometry".to_owned(), "sin_cos_f32".to_owned()]);
    let bad = core_level_breaches(&krate);
    assert_eq!(bad.len(), 2, "{bad:#?}");
}
