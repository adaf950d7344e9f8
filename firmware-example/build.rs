//! Picks the memory layout of the board, passes the linker scripts, and embeds the map.
//!
//! `MICROSLAM_MAP=<map.yaml>` (a ROS map_server map, e.g. from `host-sim replay --filter
//! grid-slam`) converts the map into a map image (`microslam::grid::map_image`, the
//! same code as `host-sim export-map`) at `$OUT_DIR/map.bin`, which the firmware embeds
//! with `include_bytes!`, and sets `cfg(microslam_map)`: the firmware then carries the
//! localizer instead of the grid SLAM. Without the variable `map.bin` is empty and the
//! firmware refuses localizer requests (`Refusal::NoMap`). The image carries the map's
//! max-pooled layers for the global search: `MICROSLAM_MAP_LEVELS` levels (default 5,
//! 0 for none). `$OUT_DIR/map_rows.rs` holds the length of the map bitmap's rows
//! (`⌈width / 8⌉` bytes, 0 without a map), so that the localizer's shift search is
//! compiled for it (`GridLocalizer::with_bitmap_row_bytes`).
//!
//! `MICROSLAM_MAP` may also name a map image (a file starting with `MSMP`): the map a
//! board wrote at the end of its SLAM run and sent back (`host-sim hil` writes it as
//! `device-map/map.bin`, `host-sim replay --loop-closure` as `map.bin`). Its bitmaps are
//! embedded as they are, with the layers made from them
//! (`microslam::grid::map_image::with_layers`).
use microslam::grid::MapImage;
use microslam::grid::map_image::{
    DEFAULT_LAYER_LEVELS, MAP_IMAGE_MAGIC, encode_map_image_with_layers, with_layers,
};
use microslam::grid::ros_map::RosMap;
use microslam::pf::GridPfConfig;
use std::{env, fs, path::PathBuf};

/// The localizer's settings (`firmware_example::config::LOCALIZER_CONFIG` is the same
/// constant): the map's cells are read with its log-odds unit and thresholds.
const MAP_CONFIG: GridPfConfig = GridPfConfig::MICROCONTROLLER;

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR is set by cargo"));
    let board = env::var_os("CARGO_FEATURE_STM32F411").is_some();
    let memory = if board && env::var_os("CARGO_FEATURE_BUILDING_SLAM").is_some() {
        // Sectors 1–2 and 6–7 kept for the SLAM's saved pose, map and keyframes.
        "memory-stm32f411-slam.x"
    } else if board {
        "memory-stm32f411.x"
    } else {
        "memory-qemu.x"
    };
    fs::copy(memory, out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={memory}");
    println!("cargo:rerun-if-changed=build.rs");
    if env::var("TARGET").is_ok_and(|t| t.starts_with("thumb")) {
        println!("cargo:rustc-link-arg-bins=--nmagic");
        println!("cargo:rustc-link-arg-bins=-Tlink.x");
        println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    }
    embed_map(&out);
}

fn embed_map(out: &std::path::Path) {
    println!("cargo:rerun-if-env-changed=MICROSLAM_MAP");
    println!("cargo:rustc-check-cfg=cfg(microslam_map)");
    let mut row_bytes = 0;
    let image = match env::var_os("MICROSLAM_MAP").filter(|v| !v.is_empty()) {
        None => Vec::new(),
        Some(yaml) => {
            let yaml = PathBuf::from(yaml);
            println!("cargo:rerun-if-changed={}", yaml.display());
            println!("cargo:rerun-if-env-changed=MICROSLAM_MAP_LEVELS");
            let levels = env::var("MICROSLAM_MAP_LEVELS").map_or(DEFAULT_LAYER_LEVELS, |v| {
                v.parse()
                    .unwrap_or_else(|_| panic!("MICROSLAM_MAP_LEVELS={v}: not a number 0..=8"))
            });
            let bytes = fs::read(&yaml)
                .unwrap_or_else(|e| panic!("MICROSLAM_MAP: {}: {e}", yaml.display()));
            if bytes.starts_with(&MAP_IMAGE_MAGIC) {
                let (image, rows) = board_map(&yaml, &bytes, levels);
                row_bytes = rows;
                fs::write(out.join("map.bin"), image).expect("write map.bin");
                write_rows(out, row_bytes);
                return;
            }
            let map = RosMap::read(&yaml, &MAP_CONFIG.log_odds)
                .unwrap_or_else(|e| panic!("MICROSLAM_MAP: {e}"));
            if (map.geometry.resolution - MAP_CONFIG.resolution).abs() > 1e-6 {
                panic!(
                    "MICROSLAM_MAP: {}: resolution {} m, the localizer runs at {} m",
                    yaml.display(),
                    map.geometry.resolution,
                    MAP_CONFIG.resolution
                );
            }
            // Levels of the global search's layers: MICROSLAM_MAP_LEVELS, default 5 (0: no
            // layers, no global search; the map alone).
            let log_odds = MAP_CONFIG.log_odds;
            let image = encode_map_image_with_layers(
                &map.cells,
                &map.geometry,
                log_odds.occupied_above,
                log_odds.free_below,
                levels,
            )
            .unwrap_or_else(|e| panic!("MICROSLAM_MAP: {}: {e}", yaml.display()));
            println!("cargo:rustc-cfg=microslam_map");
            row_bytes = map.geometry.width.div_ceil(8);
            println!(
                "cargo:warning=map {} embedded: {} x {} cells, {} layer levels, {} bytes",
                yaml.display(),
                map.geometry.width,
                map.geometry.height,
                levels,
                image.len()
            );
            image
        }
    };
    fs::write(out.join("map.bin"), image).expect("write map.bin");
    write_rows(out, row_bytes);
}

/// A board's map image, checked against the localizer's settings, with `levels` levels
/// of layers (0: as it is); and the length of its bitmap's rows.
fn board_map(path: &std::path::Path, bytes: &[u8], levels: u8) -> (Vec<u8>, usize) {
    let map =
        MapImage::parse(bytes).unwrap_or_else(|e| panic!("MICROSLAM_MAP: {}: {e}", path.display()));
    let g = *map.geometry();
    if (g.resolution - MAP_CONFIG.resolution).abs() > 1e-6
        || map.view().occupied_above() != MAP_CONFIG.log_odds.occupied_above
    {
        panic!(
            "MICROSLAM_MAP: {}: resolution {} m and occupied threshold {}, the localizer runs \
             at {} m and {}",
            path.display(),
            g.resolution,
            map.view().occupied_above(),
            MAP_CONFIG.resolution,
            MAP_CONFIG.log_odds.occupied_above
        );
    }
    let image = if levels == 0 {
        bytes.to_vec()
    } else {
        with_layers(bytes, levels)
            .unwrap_or_else(|e| panic!("MICROSLAM_MAP: {}: {e}", path.display()))
    };
    println!("cargo:rustc-cfg=microslam_map");
    println!(
        "cargo:warning=map image {} embedded: {} x {} cells, {} layer levels, {} bytes",
        path.display(),
        g.width,
        g.height,
        levels,
        image.len()
    );
    (image, g.width.div_ceil(8))
}

/// `$OUT_DIR/map_rows.rs`: the length of the embedded bitmap's rows.
fn write_rows(out: &std::path::Path, row_bytes: usize) {
    let rows = format!(
        "/// Bytes of a row of the embedded map's occupied-cell bitmap (0: no map).\n\
         pub const MAP_ROW_BYTES: usize = {row_bytes};\n"
    );
    fs::write(out.join("map_rows.rs"), rows).expect("write map_rows.rs");
}
