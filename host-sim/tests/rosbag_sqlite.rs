//! ROS 2 bags in rosbag2's SQLite 3 storage (`.db3`, the default up to ROS 2 Humble) and
//! rosbag2 bag folders (split files): the Intel log written as an MCAP bag
//! (`export-rosbag`) and copied message for message into `.db3` files with rosbag2's
//! tables reads back to the same scans, odometry and lidar; rows are played in receive-time
//! order; bad files are refused with the file named. rosbag2's compressed bags (zstd,
//! whole files or each message) read like the plain ones.

use host_sim::domain::datasets::dataset_path;
use host_sim::domain::grid::carmen_lidar;
use host_sim::inputs::readers::carmen::{LaserMessage, front_scans, read_log};
use host_sim::inputs::readers::rosbag::{self, BagOptions, MountSource, RosBag, encode_cdr, msg};
use host_sim::output::rosbag::export;
use rusqlite::{Connection, params};
use std::path::{Path, PathBuf};

/// The tables of rosbag2's SQLite storage: as the current release creates them, and as
/// the oldest releases did (`topics` without the QoS profiles and type hash, no `schema`,
/// `metadata` or `message_definitions`).
#[derive(Clone, Copy)]
enum Tables {
    Current,
    Oldest,
}

const CURRENT_TABLES: &str = "
    CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL);
    CREATE TABLE metadata(id INTEGER PRIMARY KEY, metadata_version INTEGER NOT NULL, metadata TEXT NOT NULL);
    CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
        serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL,
        type_description_hash TEXT NOT NULL);
    CREATE TABLE message_definitions(id INTEGER PRIMARY KEY, topic_type TEXT NOT NULL,
        encoding TEXT NOT NULL, encoded_message_definition TEXT NOT NULL,
        type_description_hash TEXT NOT NULL);
    CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,
        timestamp INTEGER NOT NULL, data BLOB NOT NULL);
    CREATE INDEX timestamp_idx ON messages (timestamp ASC);
    INSERT INTO schema (schema_version, ros_distro) VALUES (4, 'jazzy');";

const OLDEST_TABLES: &str = "
    CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
        serialization_format TEXT NOT NULL);
    CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,
        timestamp INTEGER NOT NULL, data BLOB NOT NULL);";

/// One stored message: topic, type, receive time (ns), CDR bytes.
type Stored = (String, String, u64, Vec<u8>);

/// The messages of an MCAP bag in file order.
fn mcap_messages(path: &Path) -> Vec<Stored> {
    let bytes = std::fs::read(path).unwrap();
    mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| {
            let m = m.unwrap();
            let schema = m.channel.schema.as_ref().unwrap().name.clone();
            (m.channel.topic.clone(), schema, m.log_time, m.data.to_vec())
        })
        .collect()
}

/// Writes `messages` into a new `.db3` file as rosbag2 does (row ids in order from 1,
/// unless `ids` gives them).
fn write_db3(path: &Path, tables: Tables, messages: &[Stored], ids: Option<&[i64]>) {
    let db = Connection::open(path).unwrap();
    db.execute_batch(match tables {
        Tables::Current => CURRENT_TABLES,
        Tables::Oldest => OLDEST_TABLES,
    })
    .unwrap();
    // One transaction, as rosbag2 writes (each statement on its own would sync the file).
    db.execute_batch("BEGIN").unwrap();
    let mut topics: Vec<&str> = Vec::new();
    for (k, (topic, schema, stamp, data)) in messages.iter().enumerate() {
        let topic_id = match topics.iter().position(|t| t == topic) {
            Some(i) => i + 1,
            None => {
                topics.push(topic);
                match tables {
                    Tables::Current => db.execute(
                        "INSERT INTO topics (name, type, serialization_format, offered_qos_profiles, type_description_hash) VALUES (?1, ?2, 'cdr', '', '')",
                        params![topic, schema],
                    ),
                    Tables::Oldest => db.execute(
                        "INSERT INTO topics (name, type, serialization_format) VALUES (?1, ?2, 'cdr')",
                        params![topic, schema],
                    ),
                }
                .unwrap();
                topics.len()
            }
        };
        let id = ids.map_or(k as i64 + 1, |ids| ids[k]);
        db.execute(
            "INSERT INTO messages (id, topic_id, timestamp, data) VALUES (?1, ?2, ?3, ?4)",
            params![id, topic_id as i64, *stamp as i64, data],
        )
        .unwrap();
    }
    db.execute_batch("COMMIT").unwrap();
}

fn intel_bag(dir: &Path) -> (PathBuf, Vec<Stored>) {
    let log = read_log(&dataset_path("intel/intel-raw-part.clf").expect("Intel log")).unwrap();
    let scans: Vec<&LaserMessage> = front_scans(&log);
    let path = dir.join("intel.mcap");
    export(&path, &scans, &carmen_lidar(180), &BagOptions::default()).unwrap();
    let messages = mcap_messages(&path);
    (path, messages)
}

/// Everything a replay takes from a bag, the file aside.
fn assert_same_bag(a: &RosBag, b: &RosBag) {
    assert_eq!(a.scans.len(), b.scans.len());
    assert_eq!(a.scans, b.scans, "the same scans and odometry poses");
    assert_eq!(a.lidar, b.lidar);
    assert_eq!(a.mount_source, b.mount_source);
    assert_eq!(a.odometry_messages, b.odometry_messages);
    assert_eq!(a.imu, b.imu);
}

#[test]
fn an_sqlite_bag_reads_like_the_mcap_bag() {
    let dir = tempfile::tempdir().unwrap();
    let (mcap, messages) = intel_bag(dir.path());
    let options = BagOptions::default();
    let from_mcap = rosbag::read(&mcap, &options).unwrap();
    assert_eq!(from_mcap.scans.len(), 5505);
    assert_eq!(from_mcap.mount_source, MountSource::TfStatic);
    for (name, tables) in [
        ("current.db3", Tables::Current),
        ("oldest.db3", Tables::Oldest),
    ] {
        let db3 = dir.path().join(name);
        write_db3(&db3, tables, &messages, None);
        let from_db3 = rosbag::read(&db3, &options).unwrap();
        assert_same_bag(&from_mcap, &from_db3);
    }
}

/// A rosbag2 bag folder `dir/name` holding `messages` in three split `.db3` files,
/// numbered 1, 2 and 10 (by name `_10` would come before `_2`), each compressed whole
/// with zstd (`<name>_1.db3.zstd`, …) when `compressed`.
fn write_split_bag(dir: &Path, name: &str, messages: &[Stored], compressed: bool) -> PathBuf {
    let bag = dir.join(name);
    std::fs::create_dir(&bag).unwrap();
    let third = messages.len() / 3;
    let parts = [
        (1, &messages[..third]),
        (2, &messages[third..2 * third]),
        (10, &messages[2 * third..]),
    ];
    for (split, part) in parts {
        let file = bag.join(format!("{name}_{split}.db3"));
        write_db3(&file, Tables::Current, part, None);
        if compressed {
            let bytes = zstd(&std::fs::read(&file).unwrap());
            std::fs::remove_file(&file).unwrap();
            std::fs::write(bag.join(format!("{name}_{split}.db3.zstd")), bytes).unwrap();
        }
    }
    bag
}

#[test]
fn a_bag_folder_reads_its_split_files_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let (mcap, messages) = intel_bag(dir.path());
    let options = BagOptions::default();
    let whole = rosbag::read(&mcap, &options).unwrap();

    // Three split files; by name `_10` would come before `_2`.
    let bag = write_split_bag(dir.path(), "intel_bag", &messages, false);
    std::fs::write(bag.join("metadata.yaml"), "rosbag2_bagfile_information:\n").unwrap();
    let split = rosbag::read(&bag, &options).unwrap();
    assert_same_bag(&whole, &split);

    // A folder holding an MCAP bag file.
    let mcap_bag = dir.path().join("mcap_bag");
    std::fs::create_dir(&mcap_bag).unwrap();
    std::fs::copy(&mcap, mcap_bag.join("mcap_bag_0.mcap")).unwrap();
    assert_same_bag(&whole, &rosbag::read(&mcap_bag, &options).unwrap());
}

/// `bytes` compressed as rosbag2's zstd compressor writes them (one Zstandard stream).
fn zstd(bytes: &[u8]) -> Vec<u8> {
    zstd::encode_all(bytes, 3).unwrap()
}

#[test]
fn compressed_bags_read_like_the_plain_bag() {
    let dir = tempfile::tempdir().unwrap();
    let (mcap, messages) = intel_bag(dir.path());
    let options = BagOptions::default();
    let whole = rosbag::read(&mcap, &options).unwrap();
    let db3 = dir.path().join("intel.db3");
    write_db3(&db3, Tables::Current, &messages, None);

    // `--compression-mode file`: each bag file one zstd stream, of either storage.
    for (plain, name) in [(&db3, "intel.db3.zstd"), (&mcap, "intel.mcap.zstd")] {
        let compressed = dir.path().join(name);
        std::fs::write(&compressed, zstd(&std::fs::read(plain).unwrap())).unwrap();
        assert_same_bag(&whole, &rosbag::read(&compressed, &options).unwrap());
    }

    // `--compression-mode message`: each message's data one zstd frame.
    let per_message: Vec<Stored> = messages
        .iter()
        .map(|(topic, schema, stamp, data)| (topic.clone(), schema.clone(), *stamp, zstd(data)))
        .collect();
    let message_db3 = dir.path().join("messages.db3");
    write_db3(&message_db3, Tables::Current, &per_message, None);
    assert_same_bag(&whole, &rosbag::read(&message_db3, &options).unwrap());

    // A bag folder of compressed split files, in split order (by name `_10` comes first).
    let bag = write_split_bag(dir.path(), "zbag", &messages, true);
    assert_same_bag(&whole, &rosbag::read(&bag, &options).unwrap());
}

#[test]
fn bad_compressed_bags_are_refused_naming_the_file_and_message() {
    let dir = tempfile::tempdir().unwrap();
    let good = [odom_at(1.0, 1.0), scan_at(2.0), odom_at(3.0, 2.0)];
    let db3 = dir.path().join("good.db3");
    write_db3(&db3, Tables::Current, &good, None);
    let compressed = zstd(&std::fs::read(&db3).unwrap());

    // A compressed file cut short.
    let cut = dir.path().join("cut.db3.zstd");
    std::fs::write(&cut, &compressed[..compressed.len() / 2]).unwrap();
    let e = error(&cut);
    assert!(
        e.contains("cut.db3.zstd") && e.contains("does not decompress"),
        "{e}"
    );

    // A compressed file that holds neither storage.
    let text = dir.path().join("text.zstd");
    std::fs::write(&text, zstd(b"rosbag2_bagfile_information:\n")).unwrap();
    let e = error(&text);
    assert!(
        e.contains("text.zstd") && e.contains("neither an MCAP nor an SQLite 3 file"),
        "{e}"
    );

    // A compressed SQLite file whose pages are overwritten.
    let mut plain = std::fs::read(&db3).unwrap();
    for b in &mut plain[100..] {
        *b = b.wrapping_mul(31).wrapping_add(7);
    }
    let garbled = dir.path().join("garbled.db3.zstd");
    std::fs::write(&garbled, zstd(&plain)).unwrap();
    let e = error(&garbled);
    assert!(e.contains("garbled.db3.zstd"), "{e}");

    // A split both plain and compressed (a compression that did not finish).
    let twice = dir.path().join("twice_bag");
    std::fs::create_dir(&twice).unwrap();
    std::fs::copy(&db3, twice.join("twice_bag_0.db3")).unwrap();
    std::fs::write(twice.join("twice_bag_0.db3.zstd"), &compressed).unwrap();
    let e = error(&twice);
    assert!(
        e.contains("twice_bag_0.db3 and") && e.contains("twice_bag_0.db3.zstd are both split 0"),
        "{e}"
    );

    // A compressed message that does not decompress: its file, row and topic named.
    let mut bad = good.clone();
    let frame = zstd(&bad[1].3);
    bad[1].3 = frame[..frame.len() - 3].to_vec();
    let messages = dir.path().join("messages.db3");
    write_db3(&messages, Tables::Current, &bad, None);
    let e = error(&messages);
    assert!(
        e.contains("messages.db3")
            && e.contains("message 2 on /scan")
            && e.contains("does not decompress"),
        "{e}"
    );
}

/// An odometry message at `t` s with the robot at `x` m, and a scan at `t`.
fn odom_at(t: f64, x: f64) -> Stored {
    let o = msg::Odometry {
        header: msg::Header {
            stamp: msg::Time::from_seconds(t),
            frame_id: "odom".into(),
        },
        child_frame_id: "base_link".into(),
        pose: msg::PoseWithCovariance {
            pose: msg::Pose {
                position: msg::Vector3 { x, y: 0.0, z: 0.0 },
                orientation: msg::Quaternion::from_yaw(0.0),
            },
            covariance: [[0.0; 6]; 6],
        },
        twist: Default::default(),
    };
    let ns = (t * 1e9) as u64;
    (
        "/odom".into(),
        msg::ODOMETRY.into(),
        ns,
        encode_cdr(&o).unwrap(),
    )
}

fn scan_at(t: f64) -> Stored {
    let s = msg::LaserScan {
        header: msg::Header {
            stamp: msg::Time::from_seconds(t),
            frame_id: "laser".into(),
        },
        angle_min: -1.0,
        angle_max: 1.0,
        angle_increment: 0.5,
        range_min: 0.1,
        range_max: 10.0,
        ranges: vec![1.0, 2.0, 3.0, 4.0, 5.0],
        ..Default::default()
    };
    let ns = (t * 1e9) as u64;
    (
        "/scan".into(),
        msg::LASER_SCAN.into(),
        ns,
        encode_cdr(&s).unwrap(),
    )
}

#[test]
fn sqlite_rows_are_played_in_receive_time_order() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("shuffled.db3");
    // Received in time order, but with row ids that are not: the odometry at 1 s is row 3.
    let messages = [odom_at(1.0, 1.0), scan_at(2.0), odom_at(3.0, 2.0)];
    write_db3(&path, Tables::Current, &messages, Some(&[3, 1, 2]));
    let bag = rosbag::read(&path, &BagOptions::default()).unwrap();
    assert_eq!(bag.scans.len(), 1);
    // Between the odometry at 1 s and at 3 s: halfway.
    assert!(
        (bag.scans[0].odom[0] - 1.5).abs() < 1e-12,
        "{:?}",
        bag.scans[0]
    );
}

fn error(path: &Path) -> String {
    format!(
        "{:#}",
        rosbag::read(path, &BagOptions::default()).unwrap_err()
    )
}

#[test]
fn bad_sqlite_bags_and_folders_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let good = [odom_at(1.0, 1.0), scan_at(2.0), odom_at(3.0, 2.0)];

    // An SQLite database that is not a bag.
    let other = dir.path().join("other.db3");
    Connection::open(&other)
        .unwrap()
        .execute_batch("CREATE TABLE things(id INTEGER PRIMARY KEY);")
        .unwrap();
    let e = error(&other);
    assert!(
        e.contains("other.db3") && e.contains("cannot read rosbag2's table `topics`"),
        "{e}"
    );

    // A message whose topic id is not in `topics`.
    let orphan = dir.path().join("orphan.db3");
    write_db3(&orphan, Tables::Current, &good, None);
    Connection::open(&orphan)
        .unwrap()
        .execute("UPDATE messages SET topic_id = 9 WHERE id = 2", [])
        .unwrap();
    let e = error(&orphan);
    assert!(
        e.contains("orphan.db3") && e.contains("message 2") && e.contains("topic id 9"),
        "{e}"
    );

    // A scan that does not decode.
    let corrupt = dir.path().join("corrupt.db3");
    let mut bad = good.clone();
    bad[1].3 = vec![0, 1, 0, 0, 7, 7];
    write_db3(&corrupt, Tables::Current, &bad, None);
    let e = error(&corrupt);
    assert!(
        e.contains("corrupt.db3") && e.contains("topic /scan, message 2"),
        "{e}"
    );

    // A file cut short, and one whose pages are overwritten.
    let whole = dir.path().join("whole.db3");
    let many: Vec<Stored> = (0..400)
        .flat_map(|k| [odom_at(f64::from(k), 0.0), scan_at(f64::from(k) + 0.5)])
        .collect();
    write_db3(&whole, Tables::Current, &many, None);
    let bytes = std::fs::read(&whole).unwrap();
    let cut = dir.path().join("cut.db3");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let e = error(&cut);
    assert!(e.contains("cut.db3"), "{e}");
    let mut scrambled = bytes.clone();
    for b in &mut scrambled[4096..] {
        *b = b.wrapping_mul(31).wrapping_add(7);
    }
    let garbled = dir.path().join("garbled.db3");
    std::fs::write(&garbled, &scrambled).unwrap();
    let e = error(&garbled);
    assert!(e.contains("garbled.db3"), "{e}");

    // A folder without bag files, and one with both storages.
    let empty = dir.path().join("empty_bag");
    std::fs::create_dir(&empty).unwrap();
    std::fs::write(
        empty.join("metadata.yaml"),
        "rosbag2_bagfile_information:\n",
    )
    .unwrap();
    let e = error(&empty);
    assert!(
        e.contains("empty_bag") && e.contains("without bag files"),
        "{e}"
    );
    let mixed = dir.path().join("mixed_bag");
    std::fs::create_dir(&mixed).unwrap();
    write_db3(&mixed.join("mixed_bag_0.db3"), Tables::Current, &good, None);
    let mcap =
        host_sim::output::mcap::McapFile::create(&mixed.join("mixed_bag_1.mcap"), "ros2").unwrap();
    mcap.finish().unwrap();
    let e = error(&mixed);
    assert!(
        e.contains("mixed_bag") && e.contains("both MCAP and SQLite"),
        "{e}"
    );

    // Split files that disagree about a topic's type.
    let disagree = dir.path().join("disagree_bag");
    std::fs::create_dir(&disagree).unwrap();
    write_db3(&disagree.join("d_0.db3"), Tables::Current, &good, None);
    let mut other_type = good.clone();
    other_type[1].1 = "sensor_msgs/msg/PointCloud2".into();
    write_db3(
        &disagree.join("d_1.db3"),
        Tables::Current,
        &other_type,
        None,
    );
    let e = error(&disagree);
    assert!(
        e.contains("d_1.db3") && e.contains("/scan") && e.contains("PointCloud2"),
        "{e}"
    );
}

#[test]
fn replay_takes_an_sqlite_bag_folder_like_the_mcap_file() {
    let log = read_log(&dataset_path("intel/intel-raw-part.clf").expect("Intel log")).unwrap();
    let scans: Vec<&LaserMessage> = front_scans(&log).into_iter().take(150).collect();
    let dir = tempfile::tempdir().unwrap();
    let mcap = dir.path().join("part.mcap");
    export(&mcap, &scans, &carmen_lidar(180), &BagOptions::default()).unwrap();
    let folder = dir.path().join("part");
    std::fs::create_dir(&folder).unwrap();
    write_db3(
        &folder.join("part_0.db3"),
        Tables::Current,
        &mcap_messages(&mcap),
        None,
    );
    let trajectory = |bag: &Path, out: &str| {
        let out = dir.path().join(out);
        let dataset = format!("rosbag:{}", bag.display());
        let run = std::process::Command::new(env!("CARGO_BIN_EXE_host-sim"))
            .args([
                "replay",
                "-q",
                "--no-plots",
                "--particles",
                "16",
                "--dataset",
            ])
            .arg(&dataset)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        std::fs::read(out.join("trajectory.tum")).unwrap()
    };
    let from_mcap = trajectory(&mcap, "mcap");
    assert_eq!(
        String::from_utf8_lossy(&from_mcap).lines().count(),
        1 + 150,
        "a header line, then a pose per scan"
    );
    assert_eq!(
        from_mcap,
        trajectory(&folder, "db3"),
        "the same trajectory, byte for byte"
    );
}

/// Runs `host-sim replay` on the bag `path`; returns its standard error, failing the test
/// when it succeeds.
fn replay_fails(path: &Path, out: &Path) -> String {
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .args(["replay", "--quiet", "--particles", "16", "--dataset"])
        .arg(format!("rosbag:{}", path.display()))
        .arg("--out")
        .arg(out)
        .output()
        .expect("host-sim starts");
    assert!(!run.status.success(), "exit 0 on {}", path.display());
    String::from_utf8_lossy(&run.stderr).to_string()
}

#[test]
fn crafted_sqlite_bags_are_refused_promptly_naming_the_file_and_the_table() {
    let dir = tempfile::tempdir().unwrap();
    // Endless rows: reading such a view would never end (issue 62's 8 KB bag).
    let endless = "WITH RECURSIVE r(x) AS (SELECT 1 UNION ALL SELECT x + 1 FROM r)";
    let topics = "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL,
        type TEXT NOT NULL, serialization_format TEXT NOT NULL);
        INSERT INTO topics VALUES (1, '/scan', 'sensor_msgs/msg/LaserScan', 'cdr'),
            (2, '/odom', 'nav_msgs/msg/Odometry', 'cdr');";
    let messages = "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,
        timestamp INTEGER NOT NULL, data BLOB NOT NULL);";
    let cases = [
        (
            "views.db3",
            format!(
                "{topics} CREATE VIEW messages AS {endless}
                 SELECT x AS id, 1 AS topic_id, x AS timestamp, x'00010000' AS data FROM r;"
            ),
            "table `messages`",
            "it is a view, not a table",
        ),
        (
            "topic_view.db3",
            format!(
                "{messages} CREATE VIEW topics AS {endless}
                 SELECT x AS id, 'a' || x AS name, 'x' AS type, 'cdr' AS serialization_format FROM r;"
            ),
            "table `topics`",
            "it is a view, not a table",
        ),
        (
            "virtual.db3",
            format!("{topics} CREATE VIRTUAL TABLE messages USING fts5(id, topic_id, timestamp, data);"),
            "table `messages`",
            "it is a virtual table",
        ),
        (
            "generated.db3",
            format!(
                "{topics} CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,
                 timestamp INTEGER NOT NULL, data BLOB GENERATED ALWAYS AS (zeroblob(100000000)));
                 INSERT INTO messages (id, topic_id, timestamp) VALUES (1, 1, 1);"
            ),
            "table `messages`",
            "its column `data` is generated or hidden",
        ),
        (
            "text_stamps.db3",
            format!(
                "{topics} CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,
                 timestamp TEXT NOT NULL, data BLOB NOT NULL);"
            ),
            "table `messages`",
            "its column `timestamp` is declared `TEXT`, rosbag2's is `INTEGER`",
        ),
        (
            "no_data.db3",
            format!(
                "{topics} CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,
                 timestamp INTEGER NOT NULL);"
            ),
            "table `messages`",
            "it has no column `data`",
        ),
    ];
    for (name, sql, table, why) in cases {
        let path = dir.path().join(name);
        Connection::open(&path)
            .unwrap()
            .execute_batch(&sql)
            .unwrap();
        let start = std::time::Instant::now();
        let e = error(&path);
        assert!(
            e.contains(name) && e.contains(table) && e.contains(why),
            "{name}: {e}"
        );
        let err = replay_fails(&path, &dir.path().join("out"));
        assert!(err.contains(name) && err.contains(why), "{name}: {err}");
        assert!(
            start.elapsed() < std::time::Duration::from_secs(20),
            "{name}: refused only after {:?}",
            start.elapsed()
        );
    }
    // The bag of the issue is small: 8 KB.
    assert!(
        std::fs::metadata(dir.path().join("views.db3"))
            .unwrap()
            .len()
            <= 8192
    );
}
