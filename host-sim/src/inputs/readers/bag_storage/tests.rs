use super::*;

#[test]
fn split_files_sort_by_their_number() {
    let n = |s: &str| split_number(Path::new(s));
    assert_eq!(n("run_0.db3"), 0);
    assert_eq!(n("dir/my_run_12.mcap"), 12);
    assert_eq!(n("run.db3"), u64::MAX);
    assert_eq!(n("run_x.db3"), u64::MAX);
    assert_eq!(n("run_3.db3.zstd"), 3);
    assert_eq!(n("run_3.mcap.zstd"), 3);
    let mut v = ["b_10.db3", "b_2.db3", "a.db3", "b_1.db3"].map(PathBuf::from);
    v.sort_by_cached_key(|p| (split_number(p), p.clone()));
    assert_eq!(
        v.map(|p| p.display().to_string()),
        ["b_1.db3", "b_2.db3", "b_10.db3", "a.db3"]
    );
}

#[test]
fn a_query_past_its_budget_of_sqlite_instructions_is_interrupted_naming_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rows.db3");
    let db = Connection::open(&path).unwrap();
    db.execute_batch(
        "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
            serialization_format TEXT NOT NULL);
         CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,
            timestamp INTEGER NOT NULL, data BLOB NOT NULL);
         INSERT INTO topics VALUES (1, '/scan', 'sensor_msgs/msg/LaserScan', 'cdr');
         WITH RECURSIVE r(x) AS (SELECT 1 UNION ALL SELECT x + 1 FROM r WHERE x < 20000)
         INSERT INTO messages SELECT x, 1, x, x'00010000' FROM r;",
    )
    .unwrap();
    drop(db);
    let open = |budget| {
        let db = Connection::open_with_flags(&path, OpenFlags::SQLITE_OPEN_READ_ONLY).unwrap();
        SqliteBag::guard_with_budget(&path, db, 1000, budget).unwrap()
    };
    let count = |bag: &SqliteBag| {
        let mut n = 0;
        sqlite_messages(&path, bag, &mut |_| {
            n += 1;
            Ok(())
        })
        .map(|()| n)
    };
    // The real budget reads every row; a small one stops the query with an error
    // naming the file, the table and the limit.
    let bag = open(SQLITE_BASE_INSTRUCTIONS);
    assert_eq!(count(&bag).unwrap(), 20000);
    let bag = open(100_000);
    let e = count(&bag).unwrap_err().to_string();
    assert!(
        e.contains("rows.db3")
            && e.contains("table `messages`")
            && e.contains("more than 100000 SQLite instructions"),
        "{e}"
    );
}

/// An MCAP file: its magic, a header, one chunk compressed with `compression` claiming
/// `uncompressed_size` and holding `records`, and nothing after (a file cut short).
fn crafted_mcap(compression: &str, uncompressed_size: u64, records: &[u8]) -> Vec<u8> {
    let mut out = MCAP_MAGIC.to_vec();
    let string = |out: &mut Vec<u8>, s: &str| {
        out.extend((s.len() as u32).to_le_bytes());
        out.extend(s.as_bytes());
    };
    let mut header = Vec::new();
    string(&mut header, "ros2");
    string(&mut header, "crafted");
    out.push(0x01);
    out.extend((header.len() as u64).to_le_bytes());
    out.extend(header);
    let mut chunk = Vec::new();
    chunk.extend(0u64.to_le_bytes());
    chunk.extend(0u64.to_le_bytes());
    chunk.extend(uncompressed_size.to_le_bytes());
    chunk.extend(0u32.to_le_bytes());
    string(&mut chunk, compression);
    chunk.extend((records.len() as u64).to_le_bytes());
    chunk.extend(records);
    out.push(0x06);
    out.extend((chunk.len() as u64).to_le_bytes());
    out.extend(chunk);
    out
}

#[test]
fn crafted_mcap_lengths_are_refused_before_their_buffers_naming_the_limit() {
    let path = Path::new("crafted.mcap");
    let read = |bytes: &[u8]| {
        let start = std::time::Instant::now();
        let e = mcap_messages(path, bytes, |_, _, _| Ok(()))
            .unwrap_err()
            .to_string();
        assert!(start.elapsed().as_secs() < 5, "{:?}", start.elapsed());
        e
    };
    // A message record inside an uncompressed chunk that claims 1 GiB − 1 bytes.
    let mut record = vec![0x05];
    record.extend(((1u64 << 30) - 1).to_le_bytes());
    let bytes = crafted_mcap("", 1 << 30, &record);
    let e = read(&bytes);
    assert!(
        e.contains("crafted.mcap")
            && e.contains("1073741823 bytes, more than the limit of 67108864 bytes"),
        "{e}"
    );
    // A zstd chunk claiming 2⁶² bytes once decompressed.
    let packed = zstd::encode_all(&[0u8; 64][..], 3).unwrap();
    let bytes = crafted_mcap("zstd", 1 << 62, &packed);
    let e = read(&bytes);
    assert!(
        e.contains("crafted.mcap") && e.contains("corrupt MCAP"),
        "{e}"
    );
    assert_eq!(mcap_record_limit(9 << 20), 1 << 30);
}

#[test]
fn a_zstd_stream_decompresses_up_to_its_limit() {
    let data: Vec<u8> = (0..3000u32).map(|k| (k % 251) as u8).collect();
    let packed = zstd::encode_all(data.as_slice(), 3).unwrap();
    let mut out = Vec::new();
    unzstd(&packed, 3000, &mut out).unwrap();
    assert_eq!(out, data, "exactly at the limit");
    out.clear();
    let e = unzstd(&packed, 2999, &mut out).unwrap_err().to_string();
    assert!(e.contains("more than 2999 bytes"), "{e}");
    let e = Unzstd::TooLarge(DECOMPRESSED_FILE_LIMIT).to_string();
    assert!(e.contains("more than 4096 MiB"), "{e}");
    // Two frames one after the other (as a concatenation of compressed parts) are one stream.
    let twice = [packed.as_slice(), packed.as_slice()].concat();
    out.clear();
    unzstd(&twice, 6000, &mut out).unwrap();
    assert_eq!(out, [data.as_slice(), data.as_slice()].concat());
    // Cut short.
    out.clear();
    let e = unzstd(&packed[..packed.len() - 4], 6000, &mut out).unwrap_err();
    assert!(matches!(e, Unzstd::Corrupt(_)), "{e}");
}
