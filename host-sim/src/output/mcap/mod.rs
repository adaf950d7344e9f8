//! MCAP files (`--mcap FILE`, `export-rosbag`): [`McapFile`] writes time-stamped messages
//! on topics with the `mcap` crate (zstd-compressed chunks, indexed, so viewers seek), and
//! [`scene`] turns a run's estimates into Foxglove messages.
//!
//! The Foxglove schemas are written as protobuf (schema encoding `protobuf`, the message
//! types and their descriptors from Foxglove's own SDK crate `foxglove`): Foxglove opens
//! them in its 3D, plot and raw-message panels, and any protobuf decoder reads them.

pub mod scene;

use anyhow::{Context, Result, anyhow};
use foxglove::Encode;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// A schema: name, encoding (`protobuf`, `ros2msg`) and its text or descriptor.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SchemaDef {
    /// Schema name (`foxglove.PoseInFrame`, `sensor_msgs/msg/LaserScan`).
    pub name: String,
    /// Schema encoding.
    pub encoding: String,
    /// The schema itself.
    pub data: Vec<u8>,
}

/// An MCAP file being written: channels are added on first use of a topic; log times are
/// kept non-decreasing (a stamp earlier than the last is written at the last: recorded
/// clocks go backwards, as in the Intel log, and viewers play in log-time order).
pub struct McapFile {
    writer: mcap::Writer<BufWriter<File>>,
    path: PathBuf,
    /// Topic → (channel id, schema name).
    channels: BTreeMap<String, (u16, String)>,
    /// Schema name → id.
    schemas: BTreeMap<String, u16>,
    sequence: u32,
    last_ns: u64,
    /// Messages written.
    pub messages: u64,
}

/// Nanoseconds of a stamp in seconds (0 for negative or non-finite stamps).
pub fn stamp_ns(stamp: f64) -> u64 {
    if stamp.is_finite() && stamp > 0.0 {
        (stamp * 1e9).round() as u64
    } else {
        0
    }
}

impl McapFile {
    /// Creates (or truncates) `path`; `profile` is the MCAP profile (`ros2` for bags, empty
    /// for Foxglove recordings).
    pub fn create(path: &Path, profile: &str) -> Result<Self> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            crate::output::create_folder(dir)?;
        }
        let file = File::create(path).with_context(|| format!("creating {}", path.display()))?;
        let writer = mcap::WriteOptions::new()
            .profile(profile)
            .library(format!("host-sim {}", env!("CARGO_PKG_VERSION")))
            // Compress on the writing thread: zstd's worker threads would compete with
            // the filter's (grid particles are scored on all cores).
            .compression_threads(0)
            .create(BufWriter::new(file))
            .with_context(|| format!("writing {}", path.display()))?;
        Ok(Self {
            writer,
            path: path.to_path_buf(),
            channels: BTreeMap::new(),
            schemas: BTreeMap::new(),
            sequence: 0,
            last_ns: 0,
            messages: 0,
        })
    }

    /// The channel of `topic`, added with `schema` and `encoding` on first use.
    fn channel(
        &mut self,
        topic: &str,
        schema: &dyn Fn() -> SchemaDef,
        encoding: &str,
    ) -> Result<u16> {
        if let Some((id, _)) = self.channels.get(topic) {
            return Ok(*id);
        }
        let s = schema();
        let schema_id = match self.schemas.get(&s.name) {
            Some(id) => *id,
            None => {
                let id = self
                    .writer
                    .add_schema(&s.name, &s.encoding, &s.data)
                    .with_context(|| format!("{}: schema {}", self.path.display(), s.name))?;
                self.schemas.insert(s.name.clone(), id);
                id
            }
        };
        let id = self
            .writer
            .add_channel(schema_id, topic, encoding, &BTreeMap::new())
            .with_context(|| format!("{}: channel {topic}", self.path.display()))?;
        self.channels.insert(topic.to_owned(), (id, s.name));
        Ok(id)
    }

    /// Writes `data` (already encoded) on `topic` at `stamp` seconds.
    pub fn write_raw(
        &mut self,
        topic: &str,
        schema: &dyn Fn() -> SchemaDef,
        encoding: &str,
        stamp: f64,
        data: &[u8],
    ) -> Result<()> {
        let channel_id = self.channel(topic, schema, encoding)?;
        let t = stamp_ns(stamp).max(self.last_ns);
        self.last_ns = t;
        self.sequence += 1;
        self.writer
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id,
                    sequence: self.sequence,
                    log_time: t,
                    publish_time: t,
                },
                data,
            )
            .with_context(|| format!("writing {} ({topic})", self.path.display()))?;
        self.messages += 1;
        Ok(())
    }

    /// Writes a Foxglove message (protobuf) on `topic` at `stamp` seconds.
    pub fn log<T: Encode>(&mut self, topic: &str, stamp: f64, message: &T) -> Result<()> {
        let mut buf = Vec::with_capacity(message.encoded_len().unwrap_or(256));
        message
            .encode(&mut buf)
            .map_err(|e| anyhow!("encoding a message for {topic}: {e}"))?;
        let schema = || {
            let s = T::get_schema().unwrap_or_else(|| foxglove::Schema::new("", "", Vec::new()));
            SchemaDef {
                name: s.name,
                encoding: s.encoding,
                data: s.data.into_owned(),
            }
        };
        self.write_raw(topic, &schema, &T::get_message_encoding(), stamp, &buf)
    }

    /// The log time, ns, a message at `stamp` gets now (never before the last one).
    pub fn log_time_ns(&self, stamp: f64) -> u64 {
        stamp_ns(stamp).max(self.last_ns)
    }

    /// Writes the summary and index and closes the file.
    pub fn finish(mut self) -> Result<PathBuf> {
        self.writer
            .finish()
            .with_context(|| format!("finishing {}", self.path.display()))?;
        Ok(self.path)
    }
}
