use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use microslam::wire::{EstimatorKind, PROTOCOL_VERSION, Refusal, Status};

use super::*;

/// A link that keeps what is written to it.
#[derive(Clone, Default)]
struct Recorder(Arc<Mutex<Vec<u8>>>);

impl Write for Recorder {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().expect("not poisoned").extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// A fresh device's answer to the handshake.
fn answer(protocol: u16, map_checksum: Option<u32>) -> ToHost {
    ToHost::Status {
        seq: 0,
        protocol,
        estimator: EstimatorKind::Ekf,
        status: Status {
            frames_ok: 1,
            ..Status::default()
        },
        stack_peak_bytes: 0,
        map_checksum,
        lidar: microslam::wire::LidarCounters::default(),
    }
}

fn status(protocol: u16) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    encode_frame(&answer(protocol, None), &mut buf)
        .expect("fits")
        .to_vec()
}

/// The handshake, a reset and a final status request.
fn stream() -> (Vec<u8>, usize) {
    let messages = [
        handshake(),
        ToDevice::Command {
            seq: 0,
            command: WireCommand::Reset {
                x: 1.0,
                y: 2.0,
                theta: 0.5,
            },
        },
        ToDevice::Command {
            seq: 1,
            command: WireCommand::ReportStatus,
        },
    ];
    let bytes = encode_all(&messages);
    let first = encode_all(&messages[..1]).len();
    (bytes, first)
}

/// Runs [`exchange`] against a device that has already sent `replies`.
fn exchange_with(bytes: Vec<u8>, replies: Vec<u8>, expected: usize) -> (Result<LinkRun>, Vec<u8>) {
    let (tx, rx) = mpsc::channel();
    if !replies.is_empty() {
        tx.send(replies).expect("receiver alive");
    }
    let link = Recorder::default();
    let written = link.0.clone();
    let expected = Expected::count(expected);
    let run =
        exchange(link, &rx, bytes, expected, Duration::from_millis(200)).map(|(run, writer)| {
            drop(writer.join());
            run
        });
    let written = written.lock().expect("not poisoned").clone();
    (run, written)
}

#[test]
fn a_device_is_an_elf_or_a_port_never_both() {
    let elf = Path::new("fw.elf");
    assert!(matches!(
        Device::from_options(Some(elf), None, 9600),
        Ok(Device::Qemu(e)) if e == elf
    ));
    assert!(matches!(
        Device::from_options(None, Some("/dev/ttyACM0"), 9600),
        Ok(Device::Serial {
            port: "/dev/ttyACM0",
            baud: 9600
        })
    ));
    for (qemu, serial) in [(Some(elf), Some("/dev/ttyACM0")), (None, None)] {
        let e = Device::from_options(qemu, serial, 9600).expect_err("refused");
        assert!(e.to_string().contains("exactly one of --qemu"), "{e}");
    }
}

#[test]
fn a_stream_opening_with_the_handshake_is_recognised() {
    let (bytes, first) = stream();
    assert_eq!(handshake_len(&bytes), Some(first));
    // A stream that opens with anything else is written at once.
    assert_eq!(handshake_len(bytes.get(first..).expect("rest")), None);
    assert_eq!(handshake_len(&[]), None);
    assert_eq!(handshake_len(&[1, 2, 3]), None);
}

#[test]
fn nothing_follows_the_handshake_until_the_device_answers_it() {
    let (bytes, first) = stream();
    let (run, written) = exchange_with(bytes.clone(), Vec::new(), 3);
    let e = run.expect_err("a silent device is refused").to_string();
    assert!(
        e.contains("did not answer the opening status request within 0.2 s"),
        "{e}"
    );
    assert_eq!(written, bytes[..first], "only the handshake was sent");

    // A device that stops (QEMU exits) is reported at once.
    let (tx, rx) = mpsc::channel::<Vec<u8>>();
    drop(tx);
    let link = Recorder::default();
    let e = exchange(
        link.clone(),
        &rx,
        bytes.clone(),
        Expected::count(3),
        Duration::from_secs(600),
    )
    .map(|_| ())
    .expect_err("refused")
    .to_string();
    assert!(e.contains("before its link closed"), "{e}");
    assert_eq!(*link.0.lock().expect("not poisoned"), bytes[..first]);

    // Garbage instead of an answer: said so.
    let (run, written) = exchange_with(bytes.clone(), vec![7, 7, 7, 0, 9, 9, 0], 3);
    let e = run.expect_err("refused").to_string();
    assert!(e.contains("2 frames from it did not decode"), "{e}");
    assert_eq!(written, bytes[..first]);
}

#[test]
fn the_answer_to_the_handshake_names_the_map_and_a_fresh_start() {
    let v = microslam::wire::PROTOCOL_VERSION;
    let check = |got: &ToHost, want: &ToHost| check_handshake(&[*got], 0, None, Some(want));
    let (a, b) = (answer(v, Some(0xAAAA_0001)), answer(v, Some(0xBBBB_0002)));
    assert!(check(&a, &a).is_ok());
    let e = check(&a, &b).expect_err("another map").to_string();
    assert!(
        e.contains("CRC-32 0xaaaa0001, the host runs on the map with CRC-32 0xbbbb0002"),
        "{e}"
    );
    let e = check(&answer(v, None), &b).expect_err("no map").to_string();
    assert!(e.contains("the device carries no valid map"), "{e}");
    // A host without a map (the EKF's reference) does not ask for one.
    assert!(check(&a, &answer(v, None)).is_ok());
    // A device that has run before: its counters are not a fresh start's.
    let mut used = a;
    if let ToHost::Status { status, .. } = &mut used {
        (status.frames_ok, status.events) = (5_000, 4_000);
    }
    let e = check(&used, &a).expect_err("not fresh").to_string();
    assert!(e.contains("reset the device before the run"), "{e}");
    // Without the host's answer only the version counts.
    assert!(check_handshake(&[used], 0, None, None).is_ok());
}

#[test]
fn a_device_answering_with_another_protocol_version_gets_nothing_more() {
    let host = microslam::wire::PROTOCOL_VERSION;
    let (bytes, first) = stream();
    let (run, written) = exchange_with(bytes.clone(), status(host + 1), 3);
    let e = run.expect_err("refused").to_string();
    assert!(
        e.contains(&format!("protocol {}, this host {host}", host + 1)),
        "{e}"
    );
    assert_eq!(written, bytes[..first]);
}

#[test]
fn a_device_that_answers_the_handshake_gets_the_whole_stream() {
    let host = microslam::wire::PROTOCOL_VERSION;
    let (bytes, first) = stream();
    let (run, written) = exchange_with(bytes.clone(), status(host), 3);
    let run = run.expect("accepted");
    assert_eq!(written, bytes, "everything was sent");
    assert_eq!(run.replies.len(), 1, "the other two never came");
    // Without a handshake the stream is written at once, whatever comes back.
    let rest = bytes.get(first..).expect("rest").to_vec();
    let (run, written) = exchange_with(rest.clone(), Vec::new(), 2);
    assert!(run.expect("no handshake, no check").replies.is_empty());
    assert_eq!(written, rest);
}

#[test]
fn a_device_of_another_protocol_version_is_refused_with_both_versions() {
    let host = microslam::wire::PROTOCOL_VERSION;
    let ok = Comparison {
        received: 3,
        device_protocol: Some(host),
        ..Comparison::default()
    };
    assert!(check_protocol(&ok).is_ok());
    let other = Comparison {
        device_protocol: Some(host + 1),
        ..ok.clone()
    };
    let e = check_protocol(&other).unwrap_err().to_string();
    assert!(
        e.contains(&format!("protocol {}, this host {host}", host + 1)),
        "{e}"
    );
    let garbled = Comparison {
        received: 0,
        bad_frames: 7,
        device_protocol: None,
        ..Comparison::default()
    };
    let e = check_protocol(&garbled).unwrap_err().to_string();
    assert!(e.contains("none of the device's 7 frames decoded"), "{e}");
    // No reply at all is another error (the device did not answer), reported elsewhere.
    assert!(check_protocol(&Comparison::default()).is_ok());
}

/// A source that never has anything to read (a silent serial port) and says when it
/// is dropped.
struct Silent(Arc<AtomicBool>);

impl Read for Silent {
    fn read(&mut self, _: &mut [u8]) -> std::io::Result<usize> {
        thread::sleep(Duration::from_millis(1));
        Err(std::io::ErrorKind::TimedOut.into())
    }
}

impl Drop for Silent {
    fn drop(&mut self) {
        self.0.store(true, Ordering::SeqCst);
    }
}

#[test]
fn the_reader_of_a_silent_port_ends_when_nobody_listens() {
    let dropped = Arc::new(AtomicBool::new(false));
    let rx = reader_thread(Silent(Arc::clone(&dropped)));
    // While the receiver lives, timeouts arrive as empty chunks and the thread reads on.
    assert_eq!(rx.recv_timeout(Duration::from_secs(5)), Ok(Vec::new()));
    assert!(!dropped.load(Ordering::SeqCst));
    drop(rx);
    // Then the thread ends and drops the port (within its next read or two).
    let deadline = Instant::now() + Duration::from_secs(10);
    while !dropped.load(Ordering::SeqCst) && Instant::now() < deadline {
        thread::sleep(Duration::from_millis(5));
    }
    assert!(
        dropped.load(Ordering::SeqCst),
        "the reader thread still holds the port"
    );
}

#[test]
fn the_comparison_names_the_first_message_answered_differently() {
    let host = vec![answer(PROTOCOL_VERSION, None); 4];
    let mut replies = host.clone();
    let run = |replies: Vec<ToHost>| LinkRun {
        replies,
        bad_frames: 0,
        elapsed: Duration::from_secs(1),
    };
    let same = compare(4, &run(replies.clone()), &host);
    assert_eq!((same.identical, same.first_difference), (4, None));
    replies[2] = answer(PROTOCOL_VERSION + 1, None);
    replies[3] = answer(PROTOCOL_VERSION + 1, None);
    let differs = compare(4, &run(replies), &host);
    assert_eq!((differs.identical, differs.first_difference), (2, Some(2)));
}

#[test]
fn the_first_refused_command_stops_the_run_with_its_reason() {
    let refused = |seq, reason| ToHost::Refused {
        seq,
        reason,
        estimator: EstimatorKind::Ekf,
    };
    let mut replies = vec![answer(PROTOCOL_VERSION, None)];
    assert!(check_refusals(&replies).is_ok());
    replies.push(refused(1, Refusal::NoMap));
    replies.push(refused(5, Refusal::InvalidEkfSetting { field: 11 }));
    let error = check_refusals(&replies).expect_err("a refusal stops the run");
    assert_eq!(
        error.to_string(),
        "the device refused command 1: the firmware carries no map"
    );
    let error = check_refusals(&replies[2..]).expect_err("a refusal stops the run");
    assert_eq!(
        error.to_string(),
        "the device refused command 5: EKF setting `bearing_std` is out of its range"
    );
}
