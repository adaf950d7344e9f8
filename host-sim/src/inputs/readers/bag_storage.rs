//! Where a ROS 2 bag's messages are stored: the two storages of rosbag2 — MCAP (`.mcap`,
//! the default since ROS 2 Iron) and SQLite 3 (`.db3`, the default up to Humble) — as one
//! file, or as a rosbag2 bag folder holding one file or several split ones
//! (`<name>_0.db3`, `<name>_1.db3`, …, beside `metadata.yaml`).
//!
//! rosbag2's compressed bags (`ros2 bag record --compression-format zstd`) are read too:
//! with `--compression-mode file` each bag file is one Zstandard stream (`<name>_0.db3.zstd`,
//! `<name>_0.mcap.zstd`), decompressed into memory when it is opened (at most
//! [`DECOMPRESSED_FILE_LIMIT`]); with `--compression-mode message` each message's data is
//! a Zstandard frame, decompressed as it is read.
//!
//! A file's storage is told by its first bytes (MCAP's, SQLite's and Zstandard's magic),
//! not by its name; a message is compressed when its data starts with Zstandard's magic
//! (uncompressed CDR starts with its encapsulation header, `00 00` or `00 01`). A folder's
//! bag files are the MCAP, SQLite and Zstandard files in it, taken in the order of
//! their split number (the digits after the last `_` of the name) and then of their name
//! (two files of one split number are an error); other files (`metadata.yaml`) are not
//! read. The messages are read in the order
//! rosbag2 plays them: an MCAP file in file order (the order rosbag2 received them), an
//! SQLite file ordered by receive time and then by row (rosbag2's `ORDER BY timestamp,
//! id`); split files one after the other.
//!
//! The SQLite tables read are those every rosbag2 release writes: `topics` (`id`, `name`,
//! `type`, `serialization_format`) and `messages` (`id`, `topic_id`, `timestamp`,
//! `data`); the columns later releases added are not needed. The files are opened
//! read-only with `rusqlite` (SQLite compiled in: no system library).

use anyhow::{Context, Result, anyhow, bail};
use rusqlite::{Connection, OpenFlags};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The first bytes of an MCAP file.
const MCAP_MAGIC: &[u8] = b"\x89MCAP0\r\n";
/// The first bytes of an SQLite 3 database file.
const SQLITE_MAGIC: &[u8] = b"SQLite format 3\0";
/// The first bytes of a Zstandard frame.
const ZSTD_MAGIC: &[u8] = b"\x28\xb5\x2f\xfd";

/// The largest a compressed bag file may be once decompressed into memory: 4 GiB. A
/// larger one is refused with a hint to decompress it on disk (`zstd -d`), from where an
/// SQLite bag is read without loading it.
pub const DECOMPRESSED_FILE_LIMIT: u64 = 4 << 30;

/// What a topic carries, as the bag declares it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Channel {
    /// The message type (`sensor_msgs/msg/LaserScan`).
    pub schema: String,
    /// The serialization (`cdr` for every ROS 2 bag).
    pub encoding: String,
}

/// One message as stored.
#[derive(Clone, Copy, Debug)]
pub struct StoredMessage<'a> {
    /// The topic.
    pub topic: &'a str,
    /// The time rosbag2 received it (ns).
    pub log_time: u64,
    /// The serialized message (CDR with its encapsulation header).
    pub data: &'a [u8],
    /// The file it is in.
    pub file: &'a Path,
    /// Its position: the index in the MCAP file, or the row id in the SQLite file.
    pub index: u64,
}

impl StoredMessage<'_> {
    /// Where the message is, for an error: the file and its position there.
    fn place(&self) -> String {
        format!(
            "{}: message {} on {}",
            self.file.display(),
            self.index,
            self.topic
        )
    }
}

/// The storage of one bag file.
enum Storage {
    /// An MCAP file, read into memory.
    Mcap(Vec<u8>),
    /// An SQLite 3 database, opened read-only, its schema checked.
    Sqlite(SqliteBag),
}

/// The files of a bag, opened.
pub struct BagFiles {
    files: Vec<(PathBuf, Storage)>,
}

impl BagFiles {
    /// Opens `path`: a bag file (MCAP or SQLite 3) or a rosbag2 bag folder.
    pub fn open(path: &Path) -> Result<Self> {
        let paths = if path.is_dir() {
            bag_files_in(path)?
        } else {
            vec![path.to_path_buf()]
        };
        let mut files = Vec::with_capacity(paths.len());
        for p in paths {
            let storage = open_file(&p)?;
            files.push((p, storage));
        }
        let mcap = files
            .iter()
            .filter(|(_, s)| matches!(s, Storage::Mcap(_)))
            .count();
        if mcap != 0 && mcap != files.len() {
            bail!(
                "{}: the folder holds both MCAP and SQLite bag files",
                path.display()
            );
        }
        Ok(Self { files })
    }

    /// Every topic of the bag with its type and encoding (a topic declared by several
    /// split files with different types is an error).
    pub fn topics(&self) -> Result<BTreeMap<String, Channel>> {
        let mut out: BTreeMap<String, Channel> = BTreeMap::new();
        for (path, storage) in &self.files {
            let found = match storage {
                Storage::Mcap(bytes) => mcap_topics(path, bytes)?,
                Storage::Sqlite(db) => sqlite_topics(path, db)?.into_values().collect(),
            };
            for (topic, channel) in found {
                match out.get(&topic) {
                    Some(seen) if *seen != channel => bail!(
                        "{}: topic {topic} carries `{}` ({}), an earlier file of the bag `{}` ({})",
                        path.display(),
                        channel.schema,
                        channel.encoding,
                        seen.schema,
                        seen.encoding
                    ),
                    Some(_) => {}
                    None => {
                        out.insert(topic, channel);
                    }
                }
            }
        }
        Ok(out)
    }

    /// Calls `each` with every message of the bag, in the order rosbag2 plays them; stops
    /// at the first error (of the storage or of `each`).
    ///
    /// A message stored compressed is handed over decompressed (at most
    /// `MCAP_RECORD_LIMIT`, 1 GiB).
    pub fn for_each_message(
        &self,
        mut each: impl FnMut(StoredMessage<'_>) -> Result<()>,
    ) -> Result<()> {
        let mut plain = Vec::new();
        let mut each = |message: StoredMessage<'_>| {
            if !message.data.starts_with(ZSTD_MAGIC) {
                return each(message);
            }
            plain.clear();
            unzstd(message.data, MCAP_RECORD_LIMIT as u64, &mut plain).map_err(|e| {
                anyhow!(
                    "{}: its zstd-compressed data does not decompress: {e}",
                    message.place()
                )
            })?;
            each(StoredMessage {
                data: &plain,
                ..message
            })
        };
        for (path, storage) in &self.files {
            match storage {
                Storage::Mcap(bytes) => {
                    let mut k = 0;
                    mcap_messages(path, bytes, |channel, log_time, data| {
                        let index = k;
                        k += 1;
                        each(StoredMessage {
                            topic: &channel.topic,
                            log_time,
                            data,
                            file: path,
                            index,
                        })
                    })?;
                }
                Storage::Sqlite(db) => sqlite_messages(path, db, &mut each)?,
            }
        }
        Ok(())
    }
}

/// The bag files in the folder `dir`, in split order.
fn bag_files_in(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut found = Vec::new();
    let entries = std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))?;
    for entry in entries {
        let path = entry
            .with_context(|| format!("reading {}", dir.display()))?
            .path();
        if path.is_file() && storage_of(&path)?.is_some() {
            found.push((split_number(&path), path));
        }
    }
    if found.is_empty() {
        bail!(
            "{}: a folder without bag files (MCAP or SQLite 3, e.g. `<name>_0.mcap` or `<name>_0.db3`)",
            dir.display()
        );
    }
    found.sort();
    // Two files of one split (`run_0.db3` beside `run_0.db3.zstd`, left by a compression
    // that did not finish) would play its messages twice.
    if let Some([(split, a), (_, b)]) = found
        .windows(2)
        .find(|w| w[0].0 != u64::MAX && w[0].0 == w[1].0)
    {
        bail!(
            "{}: {} and {} are both split {split} of the bag; keep one",
            dir.display(),
            a.display(),
            b.display(),
        );
    }
    Ok(found.into_iter().map(|(_, path)| path).collect())
}

/// The split number of a rosbag2 bag file: the digits after the last `_` of its name
/// without the extensions (`run_12.db3` and `run_12.db3.zstd` → 12); `u64::MAX` without one.
fn split_number(path: &Path) -> u64 {
    path.file_name()
        .and_then(|s| s.to_str())
        .map(|s| s.strip_suffix(".zstd").unwrap_or(s))
        .and_then(|s| Path::new(s).file_stem()?.to_str())
        .and_then(|s| s.rsplit_once('_'))
        .and_then(|(_, n)| n.parse().ok())
        .unwrap_or(u64::MAX)
}

/// What a bag file's first bytes show: one of the two storages of rosbag2, or either of
/// them compressed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Mcap,
    Sqlite,
    Zstd,
}

impl Kind {
    /// The kind `head`, a file's first bytes, shows; `None` for none.
    fn of(head: &[u8]) -> Option<Self> {
        if head.starts_with(MCAP_MAGIC) {
            Some(Self::Mcap)
        } else if head.starts_with(SQLITE_MAGIC) {
            Some(Self::Sqlite)
        } else if head.starts_with(ZSTD_MAGIC) {
            Some(Self::Zstd)
        } else {
            None
        }
    }
}

/// The storage a file's first bytes show, `None` for neither.
fn storage_of(path: &Path) -> Result<Option<Kind>> {
    use std::io::Read;
    let mut head = Vec::with_capacity(SQLITE_MAGIC.len());
    std::fs::File::open(path)
        .and_then(|f| f.take(SQLITE_MAGIC.len() as u64).read_to_end(&mut head))
        .with_context(|| format!("reading {}", path.display()))?;
    Ok(Kind::of(&head))
}

fn open_file(path: &Path) -> Result<Storage> {
    match storage_of(path)? {
        Some(Kind::Mcap) => Ok(Storage::Mcap(
            std::fs::read(path).with_context(|| format!("opening {}", path.display()))?,
        )),
        Some(Kind::Sqlite) => {
            let flags = OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX;
            let db = Connection::open_with_flags(path, flags)
                .with_context(|| format!("{}: cannot open the SQLite bag", path.display()))?;
            let bytes = std::fs::metadata(path)
                .with_context(|| format!("reading {}", path.display()))?
                .len();
            Ok(Storage::Sqlite(SqliteBag::guard(path, db, bytes)?))
        }
        Some(Kind::Zstd) => open_compressed(path),
        None => bail!(
            "{}: neither an MCAP nor an SQLite 3 file (ROS 2 bags are `.mcap` or `.db3`, or either compressed with zstd)",
            path.display()
        ),
    }
}

/// A bag file compressed whole (rosbag2's `--compression-mode file`), decompressed into
/// memory.
fn open_compressed(path: &Path) -> Result<Storage> {
    let compressed = std::fs::read(path).with_context(|| format!("opening {}", path.display()))?;
    let mut bytes = Vec::new();
    unzstd(&compressed, DECOMPRESSED_FILE_LIMIT, &mut bytes).map_err(|e| match e {
        Unzstd::TooLarge(_) => anyhow!(
            "{}: a zstd-compressed bag file too large to read in memory: {e}; decompress it with `zstd -d` and read that",
            path.display()
        ),
        Unzstd::Corrupt(_) => anyhow!(
            "{}: a zstd-compressed bag file that does not decompress: {e}",
            path.display()
        ),
    })?;
    drop(compressed);
    match Kind::of(&bytes) {
        Some(Kind::Mcap) => Ok(Storage::Mcap(bytes)),
        Some(Kind::Sqlite) => {
            let open = || {
                let mut db = Connection::open_in_memory()?;
                db.deserialize_read_exact(rusqlite::MAIN_DB, bytes.as_slice(), bytes.len(), true)?;
                Ok::<_, rusqlite::Error>(db)
            };
            let db = open().map_err(|e| {
                anyhow!(
                    "{}: cannot open the decompressed SQLite bag: {e}",
                    path.display()
                )
            })?;
            Ok(Storage::Sqlite(SqliteBag::guard(
                path,
                db,
                bytes.len() as u64,
            )?))
        }
        Some(Kind::Zstd) | None => bail!(
            "{}: zstd-compressed, but what it holds is neither an MCAP nor an SQLite 3 file",
            path.display()
        ),
    }
}

/// Why a Zstandard stream was not decompressed.
#[derive(Debug)]
enum Unzstd {
    /// Corrupt, cut short, or not Zstandard.
    Corrupt(std::io::Error),
    /// It decompresses to more than the limit (bytes).
    TooLarge(u64),
}

impl std::fmt::Display for Unzstd {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Corrupt(e) => write!(f, "{e}"),
            Self::TooLarge(limit) if limit >> 20 > 0 => {
                write!(f, "it decompresses to more than {} MiB", limit >> 20)
            }
            Self::TooLarge(limit) => write!(f, "it decompresses to more than {limit} bytes"),
        }
    }
}

/// Decompresses the Zstandard frames `data` into `out`, at most `limit` bytes.
fn unzstd(data: &[u8], limit: u64, out: &mut Vec<u8>) -> std::result::Result<(), Unzstd> {
    use std::io::Read;
    let decoder = zstd::stream::read::Decoder::with_buffer(data).map_err(Unzstd::Corrupt)?;
    let read = decoder
        .take(limit.saturating_add(1))
        .read_to_end(out)
        .map_err(Unzstd::Corrupt)?;
    if read as u64 > limit {
        return Err(Unzstd::TooLarge(limit));
    }
    Ok(())
}

/// The topics of an MCAP file (from its messages' channels).
fn mcap_topics(path: &Path, bytes: &[u8]) -> Result<Vec<(String, Channel)>> {
    let mut out = BTreeMap::new();
    mcap_messages(path, bytes, |channel, _, _| {
        out.entry(channel.topic.clone())
            .or_insert_with(|| channel.channel.clone());
        Ok(())
    })?;
    Ok(out.into_iter().collect())
}

/// The longest record an MCAP bag may hold: 1 GiB, the longest message rosbag2's SQLite
/// storage takes (SQLite's default blob limit). Longer is a corrupt length.
const MCAP_RECORD_LIMIT: usize = 1 << 30;

/// How many times larger than its file (at least 64 KiB) an MCAP record may be: a record
/// in a compressed chunk can be larger than the file, but no real bag compresses 1024 to 1,
/// so a larger length or chunk size is corrupt, refused before its buffer is allocated.
const MCAP_EXPANSION_LIMIT: usize = 1024;

/// The longest record the MCAP file of `len` bytes may hold.
fn mcap_record_limit(len: usize) -> usize {
    MCAP_RECORD_LIMIT.min(len.max(64 << 10).saturating_mul(MCAP_EXPANSION_LIMIT))
}

/// A channel of an MCAP file: its topic, type and encoding.
struct McapChannel {
    topic: String,
    channel: Channel,
}

/// Calls `each` with every message of the MCAP file `bytes` in file order (chunks
/// decompressed), with its channel, log time and data.
///
/// Read with the `mcap` crate's sans-io reader rather than its `MessageStream`, which sets
/// no record length limit: a corrupt length inside a compressed chunk made it reserve
/// that many bytes (found by the `rosbag_reader` fuzz target: an abort on 6.9 EB).
fn mcap_messages(
    path: &Path,
    bytes: &[u8],
    mut each: impl FnMut(&McapChannel, u64, &[u8]) -> Result<()>,
) -> Result<()> {
    use mcap::records::Record;
    use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
    let limit = mcap_record_limit(bytes.len());
    let corrupt = |e: mcap::McapError| match e {
        mcap::McapError::RecordTooLarge { len, .. } | mcap::McapError::ChunkTooLarge(len) => {
            anyhow!(
                "{}: truncated or corrupt MCAP: a record or chunk of {len} bytes, more than the limit of {limit} bytes for a file of {} bytes ({MCAP_EXPANSION_LIMIT} times its size, at least 64 KiB, at most 1 GiB)",
                path.display(),
                bytes.len()
            )
        }
        e => anyhow!("{}: truncated or corrupt MCAP: {e}", path.display()),
    };
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default().with_record_length_limit(limit),
    );
    let mut rest = bytes;
    let mut schemas: BTreeMap<u16, String> = BTreeMap::new();
    let mut channels: BTreeMap<u16, McapChannel> = BTreeMap::new();
    while let Some(event) = reader.next_event() {
        match event.map_err(corrupt)? {
            LinearReadEvent::ReadRequest(need) => {
                let n = need.min(rest.len());
                reader.insert(n).copy_from_slice(&rest[..n]);
                reader.notify_read(n);
                rest = &rest[n..];
            }
            LinearReadEvent::Record { data, opcode } => {
                match mcap::parse_record(opcode, data).map_err(corrupt)? {
                    Record::Schema { header, .. } => {
                        schemas.insert(header.id, header.name);
                    }
                    Record::Channel(c) => {
                        let schema = match c.schema_id {
                            0 => String::new(),
                            id => schemas.get(&id).cloned().ok_or_else(|| {
                                anyhow!(
                                    "{}: truncated or corrupt MCAP: channel {} ({}) names schema {id}, which comes nowhere before it",
                                    path.display(),
                                    c.id,
                                    c.topic
                                )
                            })?,
                        };
                        channels.insert(
                            c.id,
                            McapChannel {
                                topic: c.topic,
                                channel: Channel {
                                    schema,
                                    encoding: c.message_encoding,
                                },
                            },
                        );
                    }
                    Record::Message { header, data } => {
                        let channel = channels.get(&header.channel_id).ok_or_else(|| {
                            anyhow!(
                                "{}: truncated or corrupt MCAP: a message of channel {}, which comes nowhere before it",
                                path.display(),
                                header.channel_id
                            )
                        })?;
                        each(channel, header.log_time, &data)?;
                    }
                    _ => {}
                }
            }
        }
    }
    Ok(())
}

/// The tables of rosbag2's SQLite storage that are read, with the columns read and their
/// declared types (as every rosbag2 release creates them).
const SQLITE_TABLES: [(&str, [(&str, &str); 4]); 2] = [
    (
        "topics",
        [
            ("id", "INTEGER"),
            ("name", "TEXT"),
            ("type", "TEXT"),
            ("serialization_format", "TEXT"),
        ],
    ),
    (
        "messages",
        [
            ("id", "INTEGER"),
            ("topic_id", "INTEGER"),
            ("timestamp", "INTEGER"),
            ("data", "BLOB"),
        ],
    ),
];

/// The SQLite virtual-machine instructions one query of a bag file may take, whatever the
/// file's size: 10⁸ (about a second).
pub const SQLITE_BASE_INSTRUCTIONS: u64 = 100_000_000;

/// The SQLite instructions one query may take besides, per byte of the file: reading
/// rosbag2's real tables takes a few tens of instructions a row, and a row takes more than
/// ten bytes of the file, so this is more than ten times what any bag needs; only a
/// crafted or corrupt file reaches it.
pub const SQLITE_INSTRUCTIONS_PER_BYTE: u64 = 64;

/// The longest message (bytes) read from an SQLite bag: SQLite's own limit on a blob (its
/// default and most, 10⁹ bytes), set explicitly so that it is one that is named.
pub const SQLITE_MESSAGE_LIMIT: i32 = 1_000_000_000;

/// How often (SQLite instructions) the progress handler counts.
const SQLITE_PROGRESS_STEP: i32 = 10_000;

/// An SQLite bag file, opened read-only, hardened against a crafted file, its schema
/// checked; every query on it is bounded by a budget of SQLite instructions.
struct SqliteBag {
    db: Connection,
    /// The file's size (bytes).
    bytes: u64,
    /// The instructions one query may take.
    budget: u64,
    /// The instructions the running query has taken, counted by the progress handler.
    spent: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

impl SqliteBag {
    /// Hardens `db` (a bag file of `bytes` bytes) against a crafted file, as SQLite's
    /// "defense against the dark arts" advises: the defensive mode, an untrusted schema
    /// (no function with side effects in it), cell size checks, the blob length limit,
    /// and a progress handler that interrupts a query past its budget of instructions;
    /// then checks that `topics` and `messages` are real tables (not views or virtual
    /// tables, whose reading an input could make endless) with rosbag2's columns and
    /// declared types, before any query reads them.
    fn guard(path: &Path, db: Connection, bytes: u64) -> Result<Self> {
        let budget = SQLITE_BASE_INSTRUCTIONS
            .saturating_add(SQLITE_INSTRUCTIONS_PER_BYTE.saturating_mul(bytes));
        Self::guard_with_budget(path, db, bytes, budget)
    }

    /// [`Self::guard`] with a budget of `budget` instructions a query.
    fn guard_with_budget(path: &Path, mut db: Connection, bytes: u64, budget: u64) -> Result<Self> {
        use rusqlite::config::DbConfig;
        use rusqlite::limits::Limit;
        use std::sync::atomic::{AtomicU64, Ordering};
        let spent = std::sync::Arc::new(AtomicU64::new(0));
        let counter = spent.clone();
        let harden = |db: &mut Connection| {
            db.set_db_config(DbConfig::SQLITE_DBCONFIG_DEFENSIVE, true)?;
            db.set_db_config(DbConfig::SQLITE_DBCONFIG_TRUSTED_SCHEMA, false)?;
            db.set_limit(Limit::SQLITE_LIMIT_LENGTH, SQLITE_MESSAGE_LIMIT)?;
            db.pragma_update(None, "cell_size_check", true)?;
            db.progress_handler(
                SQLITE_PROGRESS_STEP,
                Some(move || {
                    let step = SQLITE_PROGRESS_STEP as u64;
                    counter.fetch_add(step, Ordering::Relaxed) + step > budget
                }),
            )
        };
        harden(&mut db).map_err(|e| {
            anyhow!(
                "{}: cannot set up SQLite to read the bag: {e}",
                path.display()
            )
        })?;
        let bag = Self {
            db,
            bytes,
            budget,
            spent,
        };
        for (table, columns) in SQLITE_TABLES {
            bag.check_table(path, table, &columns)?;
        }
        Ok(bag)
    }

    /// Checks that `table` is a real table with `columns` (declared types as rosbag2's,
    /// none generated).
    fn check_table(&self, path: &Path, table: &str, columns: &[(&str, &str)]) -> Result<()> {
        let listed = columns
            .iter()
            .map(|(c, _)| format!("`{c}`"))
            .collect::<Vec<_>>()
            .join(", ");
        let cannot = |why: String| {
            anyhow!(
                "{}: cannot read rosbag2's table `{table}` ({listed}): {why}",
                path.display()
            )
        };
        let sql_error = |e: rusqlite::Error| cannot(self.why(&e, "the schema"));
        self.start();
        let mut statement = self
            .db
            .prepare("SELECT type, sql FROM main.sqlite_master WHERE name = ?1 COLLATE NOCASE")
            .map_err(sql_error)?;
        let found = statement
            .query_map([table], |row| {
                Ok((row.get::<_, String>(0)?, row.get::<_, Option<String>>(1)?))
            })
            .map_err(sql_error)?
            .collect::<rusqlite::Result<Vec<_>>>()
            .map_err(sql_error)?;
        let (kind, sql) = match found.as_slice() {
            [] => return Err(cannot("the file has no such table".into())),
            [one] => one,
            _ => return Err(cannot("the schema names it more than once".into())),
        };
        if kind != "table" {
            return Err(cannot(format!(
                "it is a {kind}, not a table: refused, since reading a {kind} can take without bound"
            )));
        }
        let sql = sql.as_deref().unwrap_or("");
        let head: String = sql.split_whitespace().take(2).collect::<Vec<_>>().join(" ");
        if head.eq_ignore_ascii_case("CREATE VIRTUAL") {
            return Err(cannot(
                "it is a virtual table, not a table: refused, since reading a virtual table can take without bound".into(),
            ));
        }
        let mut statement = self
            .db
            .prepare("SELECT name, type, hidden FROM pragma_table_xinfo(?1, 'main')")
            .map_err(sql_error)?;
        let declared = statement
            .query_map([table], |row| {
                Ok((
                    row.get::<_, String>(0)?,
                    row.get::<_, String>(1)?,
                    row.get::<_, i64>(2)?,
                ))
            })
            .map_err(sql_error)?
            .collect::<rusqlite::Result<Vec<_>>>()
            .map_err(sql_error)?;
        for (column, kind) in columns {
            let Some((_, found, hidden)) = declared
                .iter()
                .find(|(name, _, _)| name.eq_ignore_ascii_case(column))
            else {
                return Err(cannot(format!("it has no column `{column}`")));
            };
            if !found.eq_ignore_ascii_case(kind) {
                return Err(cannot(format!(
                    "its column `{column}` is declared `{found}`, rosbag2's is `{kind}`"
                )));
            }
            if *hidden != 0 {
                return Err(cannot(format!(
                    "its column `{column}` is generated or hidden, not stored"
                )));
            }
        }
        Ok(())
    }

    /// Starts counting a query's instructions from 0.
    fn start(&self) {
        self.spent.store(0, std::sync::atomic::Ordering::Relaxed);
    }

    /// Why a query on `what` failed: the budget, the blob limit, or SQLite's error.
    fn why(&self, e: &rusqlite::Error, what: &str) -> String {
        use rusqlite::ErrorCode;
        match e.sqlite_error_code() {
            Some(ErrorCode::OperationInterrupted) => format!(
                "reading {what} took more than {} SQLite instructions, the limit for a bag file of {} bytes ({SQLITE_BASE_INSTRUCTIONS} + {SQLITE_INSTRUCTIONS_PER_BYTE} a byte): a crafted or corrupt file",
                self.budget, self.bytes
            ),
            Some(ErrorCode::TooBig) => format!(
                "a value in {what} is longer than the limit of {SQLITE_MESSAGE_LIMIT} bytes"
            ),
            _ => e.to_string(),
        }
    }
}

/// The `topics` table of a rosbag2 SQLite file: id → (name, channel).
fn sqlite_topics(path: &Path, bag: &SqliteBag) -> Result<BTreeMap<i64, (String, Channel)>> {
    let not_a_bag = |e: rusqlite::Error| {
        anyhow!(
            "{}: cannot read rosbag2's table `topics` (`id`, `name`, `type`, `serialization_format`): {}",
            path.display(),
            bag.why(&e, "the table `topics`")
        )
    };
    bag.start();
    let mut statement = bag
        .db
        .prepare("SELECT id, name, type, serialization_format FROM topics ORDER BY id")
        .map_err(not_a_bag)?;
    let rows = statement
        .query_map([], |row| {
            Ok((
                row.get::<_, i64>(0)?,
                (
                    row.get::<_, String>(1)?,
                    Channel {
                        schema: row.get(2)?,
                        encoding: row.get(3)?,
                    },
                ),
            ))
        })
        .map_err(not_a_bag)?;
    let mut out = BTreeMap::new();
    for row in rows {
        let (id, topic) = row.map_err(not_a_bag)?;
        out.insert(id, topic);
    }
    Ok(out)
}

/// The `messages` table of a rosbag2 SQLite file, in rosbag2's play order.
fn sqlite_messages(
    path: &Path,
    bag: &SqliteBag,
    each: &mut impl FnMut(StoredMessage<'_>) -> Result<()>,
) -> Result<()> {
    let topics = sqlite_topics(path, bag)?;
    let corrupt = |e: rusqlite::Error| {
        anyhow!(
            "{}: cannot read rosbag2's table `messages` (`id`, `topic_id`, `timestamp`, `data`): {}",
            path.display(),
            bag.why(&e, "the table `messages`")
        )
    };
    bag.start();
    let mut statement = bag
        .db
        .prepare("SELECT id, topic_id, timestamp, data FROM messages ORDER BY timestamp, id")
        .map_err(corrupt)?;
    let mut rows = statement.query([]).map_err(corrupt)?;
    while let Some(row) = rows.next().map_err(corrupt)? {
        let id: i64 = row.get(0).map_err(corrupt)?;
        let topic_id: i64 = row.get(1).map_err(corrupt)?;
        let stamp: i64 = row.get(2).map_err(corrupt)?;
        let data = row.get_ref(3).map_err(corrupt)?.as_blob().map_err(|e| {
            anyhow!(
                "{}: message {id}: its data is not a blob: {e}",
                path.display()
            )
        })?;
        let Some((topic, _)) = topics.get(&topic_id) else {
            bail!(
                "{}: message {id}: topic id {topic_id} is not in the table `topics`",
                path.display()
            );
        };
        let log_time = u64::try_from(stamp).map_err(|_| {
            anyhow!(
                "{}: message {id}: negative receive time {stamp} ns",
                path.display()
            )
        })?;
        each(StoredMessage {
            topic,
            log_time,
            data,
            file: path,
            index: id as u64,
        })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests;
