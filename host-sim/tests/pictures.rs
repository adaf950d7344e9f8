//! The pictures and the animation of a short simulator run, read back: labels where the
//! axes and legends go, the truth and the estimate both visible, the GIF's frames.

mod common;

use common::{host_sim, succeeds};
use std::path::Path;

/// The estimate's colour (vermillion) and the truth's (blue), as docs/guide.md names them.
const ESTIMATE: [u8; 3] = [213, 94, 0];
const TRUTH: [u8; 3] = [0, 114, 178];

struct Picture {
    w: u32,
    h: u32,
    px: Vec<u8>,
}

impl Picture {
    fn read(path: &Path) -> Self {
        let file = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut reader = png::Decoder::new(std::io::BufReader::new(file))
            .read_info()
            .expect("a PNG");
        let mut px = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut px).expect("a frame");
        assert_eq!(info.color_type, png::ColorType::Rgb, "{}", path.display());
        px.truncate(info.buffer_size());
        Self {
            w: info.width,
            h: info.height,
            px,
        }
    }

    fn count(&self, f: impl Fn(&[u8]) -> bool, x: (u32, u32), y: (u32, u32)) -> usize {
        (y.0..y.1.min(self.h))
            .flat_map(|r| (x.0..x.1.min(self.w)).map(move |c| 3 * (r * self.w + c) as usize))
            .filter(|&i| f(&self.px[i..i + 3]))
            .count()
    }

    fn colour(&self, c: [u8; 3]) -> usize {
        self.count(|p| p == c, (0, self.w), (0, self.h))
    }

    /// Dark (text) pixels left of the y axis (76 columns), below the x axis and its tick
    /// marks (58 rows) and in the top 40 rows (the title).
    fn text_strips(&self) -> (usize, usize, usize) {
        let dark = |p: &[u8]| p.iter().all(|c| *c < 100);
        (
            self.count(dark, (0, 76), (40, self.h - 66)),
            self.count(dark, (84, self.w), (self.h - 58, self.h)),
            self.count(dark, (0, self.w), (0, 40)),
        )
    }
}

#[test]
fn sim_pictures_are_labelled_and_the_animation_reads_back() {
    let dir = tempfile::tempdir().expect("temporary folder");
    let cfg = dir.path().join("short.toml");
    std::fs::write(&cfg, "[scenario]\nduration_s = 20.0\n").expect("config");
    let gif_path = dir.path().join("slam.gif");
    succeeds(
        host_sim()
            .args([
                "sim",
                "--seed",
                "3",
                "--quiet",
                "--grid-particles",
                "32",
                "--config",
            ])
            .arg(&cfg)
            .arg("--out")
            .arg(dir.path())
            .arg("--animate")
            .arg(&gif_path),
    );
    for name in [
        "map.png",
        "errors.png",
        "grid/slam/map.png",
        "grid/localize/map.png",
    ] {
        let p = Picture::read(&dir.path().join(name));
        assert!(p.colour(ESTIMATE) > 200, "{name}: the estimate is drawn");
        assert!(p.colour(TRUTH) > 200, "{name}: the truth is drawn");
        // Measured: about 200 dark pixels in each strip; none without text.
        let (left, bottom, top) = p.text_strips();
        assert!(left > 120, "{name}: y axis labels ({left} dark pixels)");
        assert!(bottom > 120, "{name}: x axis labels ({bottom} dark pixels)");
        assert!(top > 120, "{name}: title ({top} dark pixels)");
    }
    let scans = serde_json::from_str::<serde_json::Value>(
        &std::fs::read_to_string(dir.path().join("grid/slam/metrics.json")).expect("metrics"),
    )
    .expect("json")["scans"]
        .as_u64()
        .expect("scans") as usize;
    // 150 frames wanted: a snapshot every ⌈scans / 150⌉ scans and after the last, plus the
    // starting map.
    let every = scans.div_ceil(150);
    let frames_expected = 1 + scans.div_ceil(every);
    let mut options = gif::DecodeOptions::new();
    options.set_color_output(gif::ColorOutput::Indexed);
    let mut decoder = options
        .read_info(std::fs::File::open(&gif_path).expect("the GIF exists"))
        .expect("a GIF");
    let (w, h) = (u32::from(decoder.width()), u32::from(decoder.height()));
    assert!((360..=480).contains(&w) && h <= 480 + 60, "{w} × {h}");
    let mut frames = 0;
    while let Some(frame) = decoder.read_next_frame().expect("a frame") {
        if frames == 0 {
            assert_eq!((u32::from(frame.width), u32::from(frame.height)), (w, h));
        }
        assert!(u32::from(frame.left + frame.width) <= w);
        assert!(u32::from(frame.top + frame.height) <= h);
        frames += 1;
    }
    assert_eq!(frames, frames_expected, "{scans} scans");
}
