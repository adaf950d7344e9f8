use super::*;
use crate::ekf::{factor_len, state_dim};
use crate::wire::EkfSettings;
use crate::wire::encode_frame;

fn frames(msgs: &[ToDevice]) -> std::vec::Vec<u8> {
    let mut out = std::vec::Vec::new();
    let mut buf = [0u8; MAX_FRAME_LEN];
    for m in msgs {
        out.extend_from_slice(encode_frame(m, &mut buf).unwrap());
    }
    out
}

fn velocity(seq: u32, v: f32, omega: f32) -> ToDevice {
    ToDevice::Odometry {
        seq,
        stamp_us: u64::from(seq) * 100_000,
        odometry: Odometry::Velocity { v, omega, dt: 0.1 },
    }
}

fn sighting(seq: u32, id: u32, range: f32, bearing: f32) -> ToDevice {
    ToDevice::Landmark {
        seq,
        stamp_us: u64::from(seq) * 100_000,
        id,
        range,
        bearing,
    }
}

#[test]
fn every_status_names_the_map_the_session_was_given() {
    let mut ekf = EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
    let ask = frames(&[ToDevice::Command {
        seq: 1,
        command: Command::ReportStatus,
    }]);
    let map_of =
        |session: &mut Session<'_, _, _, 4>| match ask.iter().find_map(|&b| session.receive(b)) {
            Some(ToHost::Status { map_checksum, .. }) => map_checksum,
            other => panic!("{other:?}"),
        };
    let mut plain = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32);
    assert_eq!(map_of(&mut plain), None);
    drop(plain);
    let mut named = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32)
        .with_map_checksum(Some(0x1234_5678));
    assert_eq!(map_of(&mut named), Some(0x1234_5678));
    // A reset does not forget it.
    let reset = frames(&[ToDevice::Command {
        seq: 2,
        command: Command::Reset {
            x: 1.0,
            y: 0.0,
            theta: 0.0,
        },
    }]);
    assert_eq!(reset.iter().filter_map(|&b| named.receive(b)).count(), 1);
    assert_eq!(map_of(&mut named), Some(0x1234_5678));
}

#[test]
fn a_map_is_saved_and_read_only_where_there_is_one() {
    let mut ekf = EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
    let mut session = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32);
    let replies: std::vec::Vec<ToHost> = frames(&[
        ToDevice::Command {
            seq: 1,
            command: Command::SaveMap,
        },
        ToDevice::Command {
            seq: 2,
            command: Command::ReadMap { offset: 0 },
        },
    ])
    .into_iter()
    .filter_map(|b| session.receive(b))
    .collect();
    // The EKF keeps no map image; nothing was saved to read.
    assert_eq!(
        replies,
        [
            ToHost::Refused {
                seq: 1,
                reason: Refusal::NoMapStorage,
                estimator: EstimatorKind::Ekf,
            },
            ToHost::Refused {
                seq: 2,
                reason: Refusal::NoSavedMap,
                estimator: EstimatorKind::Ekf,
            },
        ]
    );
}

#[test]
fn replies_match_direct_calls_on_the_filter() {
    let msgs = [
        sighting(1, 40, 2.0, 0.3),
        velocity(2, 0.5, 0.1),
        sighting(3, 40, 1.95, 0.33),
        sighting(4, 41, 3.0, -0.5),
        velocity(5, 0.5, 0.1),
        sighting(6, 41, 2.9, -0.52),
        sighting(7, 40, f32::NAN, 0.0),
    ];
    let mut ekf = EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
    let mut session = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32);
    let mut replies = std::vec::Vec::new();
    for b in frames(&msgs) {
        replies.extend(session.receive(b));
    }
    let mut direct =
        EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
    let a = direct.add_landmark(&RangeBearing::new(2.0, 0.3)).unwrap();
    direct.predict_velocity(0.5, 0.1, 0.1).unwrap();
    direct.update(a, &RangeBearing::new(1.95, 0.33)).unwrap();
    let b = direct.add_landmark(&RangeBearing::new(3.0, -0.5)).unwrap();
    direct.predict_velocity(0.5, 0.1, 0.1).unwrap();
    direct.update(b, &RangeBearing::new(2.9, -0.52)).unwrap();

    assert_eq!(replies.len(), msgs.len());
    let results: std::vec::Vec<_> = replies
        .iter()
        .map(|r| match r {
            ToHost::Estimate(e) => (e.seq, e.result),
            other => panic!("{other:?}"),
        })
        .collect();
    let nonfinite = StepResult::Rejected {
        reason: crate::EkfError::NonFiniteInput as u8,
    };
    assert_eq!(
        results,
        [
            (1, StepResult::Added),
            (2, StepResult::Applied),
            (3, StepResult::Applied),
            (4, StepResult::Added),
            (5, StepResult::Applied),
            (6, StepResult::Applied),
            (7, nonfinite),
        ]
    );
    let ToHost::Estimate(last) = replies[6] else {
        unreachable!()
    };
    let pose = direct.pose();
    assert_eq!(last.pose, [pose.x, pose.y, pose.theta]);
    let p = direct.pose_covariance();
    assert_eq!(last.covariance[0], p[(0, 0)]);
    assert_eq!(last.covariance[4], p[(1, 2)]);
    assert_eq!(last.status.landmarks, 2);
    assert_eq!(last.status.events, 7);
    assert_eq!(last.status.rejected, 1);
    assert_eq!(last.status.frames_ok, 7);
}

#[test]
fn ekf_settings_from_the_wire_replace_the_configuration() {
    let mut ekf = EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
    let mut session = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32);
    let mut wanted = EkfConfig::MICROCONTROLLER;
    wanted.range_std = 0.123;
    wanted.gate = crate::gate::ChiSquareGate::from_threshold(7.5);
    wanted.sensor =
        crate::sensors::range_bearing::RangeBearingSensor::new(Pose2::new(0.1, -0.02, 0.05));
    let settings = EkfSettings::from_config(&wanted);
    assert_eq!(settings.to_config(), wanted);
    let mut bad = settings;
    bad.bearing_std = f32::NAN;
    let bytes = frames(&[
        ToDevice::Command {
            seq: 1,
            command: Command::ConfigureEkf(settings),
        },
        ToDevice::Command {
            seq: 2,
            command: Command::ConfigureEkf(bad),
        },
    ]);
    let replies: std::vec::Vec<_> = bytes.iter().filter_map(|&b| session.receive(b)).collect();
    // The valid settings are taken; the NaN ones refused, the value named (the
    // bearing's standard deviation is the twelfth value on the wire) and counted.
    assert!(
        matches!(replies[0], ToHost::Status { seq: 1, status, .. } if status.rejected == 0),
        "{:?}",
        replies[0]
    );
    assert_eq!(
        replies[1],
        ToHost::Refused {
            seq: 2,
            reason: Refusal::InvalidEkfSetting { field: 11 },
            estimator: EstimatorKind::Ekf,
        }
    );
    let status = frames(&[ToDevice::Command {
        seq: 3,
        command: Command::ReportStatus,
    }]);
    let counted: std::vec::Vec<_> = status.iter().filter_map(|&b| session.receive(b)).collect();
    assert!(
        matches!(counted[..], [ToHost::Status { status, .. }] if status.rejected == 1),
        "{counted:?}"
    );
    // A reset keeps them.
    let reset = frames(&[ToDevice::Command {
        seq: 3,
        command: Command::Reset {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
        },
    }]);
    assert_eq!(reset.iter().filter_map(|&b| session.receive(b)).count(), 1);
    drop(session);
    assert_eq!(*ekf.config(), wanted);
}

#[test]
fn bad_frames_are_counted_and_commands_answered_with_status() {
    let mut ekf = EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
    let mut session = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32);
    let mut bytes = frames(&[sighting(1, 7, 2.0, 0.0)]);
    bytes.extend_from_slice(&[1, 2, 3, 0, 0xff, 0xfe, 0]);
    bytes.extend(frames(&[
        ToDevice::Command {
            seq: 2,
            command: Command::Reset {
                x: 1.0,
                y: 2.0,
                theta: 0.5,
            },
        },
        ToDevice::Command {
            seq: 3,
            command: Command::SelectEstimator(EstimatorKind::Grid),
        },
        velocity(4, 0.0, 0.0),
    ]));
    let replies: std::vec::Vec<_> = bytes.iter().filter_map(|&b| session.receive(b)).collect();
    assert_eq!(replies.len(), 4);
    match replies[1] {
        ToHost::Status { seq, status, .. } => {
            assert_eq!(seq, 2);
            assert_eq!(status.frames_bad, 2);
            assert_eq!(status.landmarks, 0);
            assert_eq!(status.events, 0);
        }
        other => panic!("{other:?}"),
    }
    // No grid in this session: it stays on the EKF, restarted at the origin.
    assert!(matches!(
        replies[2],
        ToHost::Status {
            seq: 3,
            estimator: EstimatorKind::Ekf,
            ..
        }
    ));
    match replies[3] {
        ToHost::Estimate(e) => {
            assert_eq!(e.seq, 4);
            assert_eq!(e.pose, [0.0, 0.0, 0.0]);
            assert_eq!(e.status.frames_ok, 4);
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn grid_session_matches_direct_calls_on_the_grid_slam() {
    use crate::grid::OccupancyGrid;
    use crate::pf::{GridPfConfig, GridSlam};
    use crate::wire::ScanChunk;
    type Slam<'g> = GridSlam<'g, 64, 64, 8, 40>;
    let config = GridPfConfig::MICROCONTROLLER;
    let setup = GridSetup {
        wheels: DiffDriveGeometry {
            metres_per_tick: 0.002,
            track_width: 0.4,
        },
        ..GridSetup::EXAMPLE
    };
    // A square room 2.4 m wide seen from the centre: 40 beams, 0 mm = no return.
    let inc = core::f32::consts::TAU / 40.0;
    let ranges_mm: std::vec::Vec<u16> = (0..40)
        .map(|i| {
            let a = -core::f32::consts::PI + inc * i as f32;
            let r = 1.2 / libm::fabsf(libm::cosf(a)).max(libm::fabsf(libm::sinf(a)));
            if i == 5 { 0 } else { (r * 1000.0) as u16 }
        })
        .collect();
    let chunk = |seq: u32, scan_id: u16, offset: usize| {
        let end = (offset + 32).min(40);
        ToDevice::Scan(ScanChunk {
            seq,
            stamp_us: 0,
            scan_id,
            beam_offset: offset as u16,
            beam_total: 40,
            angle_min: -core::f32::consts::PI,
            angle_increment: inc,
            ranges_mm: heapless::Vec::from_slice(&ranges_mm[offset..end]).unwrap(),
        })
    };
    let ticks = ToDevice::Odometry {
        seq: 9,
        stamp_us: 0,
        odometry: Odometry::EncoderTicks {
            front_left: 10,
            front_right: 14,
            rear_left: 10,
            rear_right: 14,
            dt: 0.1,
        },
    };
    let msgs = [
        chunk(1, 0, 0), // EKF active: ignored
        ToDevice::Command {
            seq: 2,
            command: Command::SelectEstimator(EstimatorKind::Grid),
        },
        chunk(3, 1, 0),
        chunk(4, 1, 32),
        velocity(5, 0.2, 0.1),
        chunk(6, 2, 32), // first chunk lost: dropped
        chunk(7, 3, 0),
        chunk(8, 3, 32),
        ticks,
        chunk(10, 4, 0),
        chunk(11, 4, 32),
    ];
    let mut ekf = EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
    let mut grid = std::boxed::Box::new(OccupancyGrid::<64, 64>::centred(
        config.resolution,
        config.log_odds,
    ));
    let mut slam = Slam::new(&mut grid, config, Pose2::new(0.0, 0.0, 0.0)).unwrap();
    let mut session =
        Session::<_, _, 4>::with_grid(&mut ekf, EkfConfig::DEFAULT_F32, &mut slam, setup);
    let replies: std::vec::Vec<_> = frames(&msgs)
        .iter()
        .filter_map(|&b| session.receive(b))
        .collect();
    drop(session);

    let mut grid2 = std::boxed::Box::new(OccupancyGrid::<64, 64>::zeroed());
    grid2
        .init_centred(config.resolution, config.log_odds)
        .unwrap();
    let mut direct = Slam::new(&mut grid2, config, Pose2::new(0.0, 0.0, 0.0)).unwrap();
    let ranges: std::vec::Vec<f32> = ranges_mm
        .iter()
        .map(|&mm| {
            if mm == 0 {
                f32::NAN
            } else {
                f32::from(mm) * 0.001
            }
        })
        .collect();
    let lidar = LidarGeometry {
        first_angle: -core::f32::consts::PI,
        angle_increment: inc,
        ..setup.lidar
    };
    direct.observe(&LidarScan::new(&ranges, lidar)).unwrap();
    direct.predict_velocity(0.2, 0.1, 0.1).unwrap();
    direct.observe(&LidarScan::new(&ranges, lidar)).unwrap();
    // Left 10 ticks, right 14 ticks (front and rear averaged) of 2 mm on a 0.4 m track.
    let m = setup
        .wheels
        .motion(&WheelTicks {
            front_right: 14,
            front_left: 10,
            rear_right: 14,
            rear_left: 10,
        })
        .unwrap();
    assert!((m.distance - 0.024).abs() < 1e-6 && (m.heading_change - 0.02).abs() < 1e-6);
    direct.predict(m.distance, m.heading_change).unwrap();
    direct.observe(&LidarScan::new(&ranges, lidar)).unwrap();

    let results: std::vec::Vec<_> = replies
        .iter()
        .map(|r| match r {
            ToHost::Estimate(e) => (e.seq, e.estimator, e.result),
            ToHost::Status { seq, estimator, .. } => (*seq, *estimator, StepResult::Ignored),
            other => panic!("{other:?}"),
        })
        .collect();
    use EstimatorKind::{Ekf, Grid};
    use StepResult::{Applied, Ignored};
    assert_eq!(
        results,
        [
            (1, Ekf, Ignored),
            (2, Grid, Ignored),
            (3, Grid, Ignored),
            (4, Grid, Applied),
            (5, Grid, Applied),
            (
                6,
                Grid,
                StepResult::Rejected {
                    reason: SCAN_DROPPED
                }
            ),
            (7, Grid, Ignored),
            (8, Grid, Applied),
            (9, Grid, Applied),
            (10, Grid, Ignored),
            (11, Grid, Applied),
        ]
    );
    let ToHost::Estimate(last) = replies[10] else {
        unreachable!()
    };
    let pose = direct.pose();
    assert_eq!(last.pose, [pose.x, pose.y, pose.theta]);
    assert_eq!(last.status.resamples, direct.filter().resample_count());
    assert_eq!(last.covariance, direct.filter().pose_covariance());
    assert!(last.covariance[0] > 0.0 && last.covariance[3] > 0.0 && last.covariance[5] > 0.0);
}

#[test]
fn localizer_mode_matches_direct_calls_and_refusals_are_explicit() {
    use crate::grid::{GridGeometry, GridView, MaxPoolLayers};
    use crate::pf::{GridPfConfig, RelocalizationConfig};
    use crate::wire::{LocalizerReport, Refusal, ScanChunk, TrackingState};
    let config = GridPfConfig::MICROCONTROLLER;
    // A square room, walls at ±1.2 m, on a 64 × 64 map of 5 cm cells.
    let g = GridGeometry::centred(64, 64, 0.05);
    let cells: std::vec::Vec<i8> = (0..64 * 64)
        .map(|i| {
            let (x, y) = g.cell_centre(i % 64, i / 64);
            let d = x.abs().max(y.abs());
            if (1.175..1.25).contains(&d) {
                100
            } else if d < 1.175 {
                -100
            } else {
                0
            }
        })
        .collect();
    let view = GridView::new(&cells, g, config.log_odds.occupied_above).unwrap();
    let mut layers = vec![0u8; MaxPoolLayers::bytes_for(64, 64, 3).unwrap()];
    let layers = MaxPoolLayers::build(&view, config.log_odds.free_below, 3, &mut layers).unwrap();
    let inc = core::f32::consts::TAU / 40.0;
    let ranges_mm: std::vec::Vec<u16> = (0..40)
        .map(|i| {
            let a = -core::f32::consts::PI + inc * i as f32;
            let r = 1.2 / libm::fabsf(libm::cosf(a)).max(libm::fabsf(libm::sinf(a)));
            (r * 1000.0) as u16
        })
        .collect();
    let chunk = |seq: u32, offset: usize| {
        ToDevice::Scan(ScanChunk {
            seq,
            stamp_us: 0,
            scan_id: seq as u16,
            beam_offset: offset as u16,
            beam_total: 40,
            angle_min: -core::f32::consts::PI,
            angle_increment: inc,
            ranges_mm: heapless::Vec::from_slice(&ranges_mm[offset..(offset + 32).min(40)])
                .unwrap(),
        })
    };
    let command = |seq, command| ToDevice::Command { seq, command };
    let msgs = [
        command(1, Command::Relocalize),
        command(2, Command::SelectEstimator(EstimatorKind::Localizer)),
        command(
            3,
            Command::Reset {
                x: 0.05,
                y: 0.0,
                theta: 0.0,
            },
        ),
        chunk(4, 0),
        chunk(4, 32),
        velocity(5, 0.0, 0.0),
        command(6, Command::Relocalize),
        chunk(7, 0),
        chunk(7, 32),
    ];
    let bytes = frames(&msgs);
    let setup = GridSetup::EXAMPLE;

    // Without a map: both commands refused, the EKF stays.
    let mut ekf = EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
    let mut plain = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32);
    let replies: std::vec::Vec<_> = bytes.iter().filter_map(|&b| plain.receive(b)).collect();
    let refused = |seq, reason| ToHost::Refused {
        seq,
        reason,
        estimator: EstimatorKind::Ekf,
    };
    assert_eq!(replies[0], refused(1, Refusal::NotLocalizing));
    assert_eq!(replies[1], refused(2, Refusal::NoMap));
    drop(plain);
    let mut bad = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32)
        .with_localizer(Err(Refusal::BadMap { code: 6 }), setup);
    let replies: std::vec::Vec<_> = bytes.iter().filter_map(|&b| bad.receive(b)).collect();
    assert_eq!(replies[1], refused(2, Refusal::BadMap { code: 6 }));
    drop(bad);

    // With the map and its layers.
    let start = Pose2::new(0.0, 0.0, 0.0);
    let mut loc = GridLocalizer::<16, 40>::new(view, config, start)
        .unwrap()
        .with_layers(layers, RelocalizationConfig::DEFAULT)
        .unwrap();
    let mut session = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32)
        .with_localizer(Ok(&mut loc), setup);
    let replies: std::vec::Vec<_> = bytes.iter().filter_map(|&b| session.receive(b)).collect();
    drop(session);
    assert_eq!(replies.len(), msgs.len());
    assert_eq!(replies[0], refused(1, Refusal::NotLocalizing));
    assert!(matches!(
        replies[1],
        ToHost::Status {
            seq: 2,
            estimator: EstimatorKind::Localizer,
            ..
        }
    ));
    let localization = |r: &ToHost| match r {
        ToHost::Localization {
            estimate,
            localizer,
        } => (*estimate, *localizer),
        other => panic!("{other:?}"),
    };
    assert_eq!(localization(&replies[3]).0.result, StepResult::Ignored);
    let (after_scan, report) = localization(&replies[4]);
    assert_eq!(after_scan.result, StepResult::Applied);
    assert_eq!(report.state, TrackingState::Tracking);
    assert!(report.hit_fraction > 0.5, "{report:?}");

    // The same steps on a twin, called directly.
    let mut twin = GridLocalizer::<16, 40>::new(view, config, start).unwrap();
    twin.reset_around(Pose2::new(0.05, 0.0, 0.0), 0.0, 0.0)
        .unwrap();
    let ranges: std::vec::Vec<f32> = ranges_mm.iter().map(|&mm| f32::from(mm) * 0.001).collect();
    let lidar = LidarGeometry {
        first_angle: -core::f32::consts::PI,
        angle_increment: inc,
        ..setup.lidar
    };
    twin.observe(&LidarScan::new(&ranges, lidar)).unwrap();
    let pose = twin.pose();
    assert_eq!(after_scan.pose, [pose.x, pose.y, pose.theta]);
    assert_eq!(after_scan.covariance, twin.filter().pose_covariance());

    // A session started on the localizer from a pose (kept in flash across a reset)
    // answers the same scan as one told to reset there, and names the localizer at once.
    let mut loc = GridLocalizer::<16, 40>::new(view, config, start)
        .unwrap()
        .with_layers(layers, RelocalizationConfig::DEFAULT)
        .unwrap();
    let mut resumed = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32)
        .with_localizer(Ok(&mut loc), setup)
        .localizing_from(Pose2::new(0.05, 0.0, 0.0));
    assert_eq!(resumed.active(), EstimatorKind::Localizer);
    let scan = frames(&[chunk(4, 0), chunk(4, 32)]);
    let replies_resumed: std::vec::Vec<_> =
        scan.iter().filter_map(|&b| resumed.receive(b)).collect();
    assert_eq!(localization(&replies_resumed[1]).0.pose, after_scan.pose);
    assert!(!resumed.restart_requested());
    let restart = frames(&[command(9, Command::Restart)]);
    let answer: std::vec::Vec<_> = restart.iter().filter_map(|&b| resumed.receive(b)).collect();
    assert!(
        matches!(
            answer[..],
            [ToHost::Status {
                seq: 9,
                estimator: EstimatorKind::Localizer,
                ..
            }]
        ),
        "{answer:?}"
    );
    assert!(resumed.restart_requested());
    drop(resumed);
    // Without a localizer a session cannot start on it: it stays on the EKF.
    let plain = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32)
        .localizing_from(Pose2::new(1.0, 0.0, 0.0));
    assert_eq!(plain.active(), EstimatorKind::Ekf);
    drop(plain);

    // Relocalize: answered with a status; the next scan runs the global search.
    assert!(matches!(replies[6], ToHost::Status { seq: 6, .. }));
    let (_, report) = localization(&replies[8]);
    assert_eq!(report.relocalizations, 1, "{report:?}");
    assert_eq!(
        report.search_scans, 0,
        "the search ended on its scan: {report:?}"
    );
    assert_ne!(report, LocalizerReport::default());

    // A search spanning scans (5 units of work, about a node, a scan; at most 3
    // scans): each estimate says
    // how many scans it has run, until it ends (seeded or failed) on the third.
    let slow = RelocalizationConfig {
        search: crate::pf::global::GlobalSearchConfig {
            work_budget: 5,
            ..crate::pf::global::GlobalSearchConfig::DEFAULT
        },
        search_scans: 3,
        ..RelocalizationConfig::DEFAULT
    };
    let mut loc = GridLocalizer::<16, 40>::new(view, config, start)
        .unwrap()
        .with_layers(layers, slow)
        .unwrap();
    let mut session = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32)
        .with_localizer(Ok(&mut loc), setup);
    let msgs = [
        command(1, Command::SelectEstimator(EstimatorKind::Localizer)),
        command(2, Command::Relocalize),
        chunk(3, 0),
        chunk(3, 32),
        chunk(4, 0),
        chunk(4, 32),
        chunk(5, 0),
        chunk(5, 32),
    ];
    let replies: std::vec::Vec<_> = frames(&msgs)
        .iter()
        .filter_map(|&b| session.receive(b))
        .collect();
    drop(session);
    assert_eq!(replies.len(), msgs.len());
    let reports: std::vec::Vec<_> = [3, 5, 7].map(|i| localization(&replies[i]).1).to_vec();
    assert_eq!(reports[0].search_scans, 1, "{reports:?}");
    assert_eq!(reports[0].state, TrackingState::Lost);
    assert_eq!(reports[1].search_scans, 2, "{reports:?}");
    assert_eq!(reports[2].search_scans, 0, "{reports:?}");
    // Ended: seeded (relocalized), or failed and lost (the next scan searches again).
    let s = *loc.status();
    assert_eq!(s.relocalizations + s.failed_searches, 1, "{s:?}");
    assert_eq!(reports[2].relocalizations, s.relocalizations);
    assert_eq!(
        reports[2].state == TrackingState::Lost,
        s.failed_searches == 1,
        "{reports:?}"
    );
}

/// A car: its odometry is rejected until a model is configured, an invalid model is
/// refused (and counted), and then each `Ackermann` step equals `predict_ackermann` on a
/// filter of its own. Without the feature `car` both are refused.
#[test]
fn a_car_moves_the_ekf_through_the_configured_model() {
    use crate::motion::{Ackermann, AckermannNoise};
    use crate::wire::CarSettings;
    let car = Ackermann {
        wheelbase: 0.3f32,
        max_steering: 0.6,
        noise: AckermannNoise {
            speed_std: 0.01,
            speed_std_per_mps: 0.05,
            steering_std: 0.02,
            steering_std_per_mps: 0.0,
        },
    };
    let drive = |seq: u32, steering: f32| ToDevice::Odometry {
        seq,
        stamp_us: u64::from(seq) * 100_000,
        odometry: Odometry::Ackermann {
            v: 0.4,
            steering,
            dt: 0.1,
        },
    };
    let configure = |seq: u32, car: &Ackermann<f32>| ToDevice::Command {
        seq,
        command: Command::ConfigureCar(CarSettings::from_model(car)),
    };
    let invalid = Ackermann {
        wheelbase: 0.0,
        ..car
    };
    let mut ekf = EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
    let mut session = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32);
    let replies: std::vec::Vec<ToHost> = frames(&[
        drive(1, 0.1),
        configure(2, &invalid),
        configure(3, &car),
        drive(4, 0.1),
        drive(5, -0.3),
        drive(6, 0.9), // beyond max_steering: a corrupt reading
    ])
    .iter()
    .filter_map(|&b| session.receive(b))
    .collect();
    let result = |r: &ToHost| match r {
        ToHost::Estimate(e) => Some(e.result),
        _ => None,
    };
    assert_eq!(
        result(&replies[0]),
        Some(StepResult::Rejected { reason: NO_CAR })
    );
    if !cfg!(feature = "car") {
        assert!(matches!(
            replies[2],
            ToHost::Refused {
                reason: Refusal::NoCarModel,
                ..
            }
        ));
        return;
    }
    assert!(matches!(
        replies[1],
        ToHost::Refused {
            reason: Refusal::InvalidCar,
            ..
        }
    ));
    assert!(
        matches!(replies[2], ToHost::Status { .. }),
        "{:?}",
        replies[2]
    );
    assert_eq!(result(&replies[3]), Some(StepResult::Applied));
    assert_eq!(result(&replies[4]), Some(StepResult::Applied));
    assert!(matches!(
        result(&replies[5]),
        Some(StepResult::Rejected { .. })
    ));
    // The same steps on a filter of its own.
    let mut direct =
        EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
    direct.predict_ackermann(&car, 0.4, 0.1, 0.1).unwrap();
    direct.predict_ackermann(&car, 0.4, -0.3, 0.1).unwrap();
    let ToHost::Estimate(last) = replies[4] else {
        panic!("{:?}", replies[4]);
    };
    let p = direct.pose();
    assert_eq!(last.pose, [p.x, p.y, p.theta]);
    assert!(p.x > 0.07 && p.theta < 0.0, "{p:?}");
}

/// A lidar that finishes the revolutions it is given, then fails (its bus went quiet).
#[cfg(feature = "own-lidar")]
struct Revolutions {
    ranges: std::vec::Vec<std::vec::Vec<f32>>,
    next: usize,
    current: std::vec::Vec<f32>,
}

#[cfg(feature = "own-lidar")]
impl LidarSource for Revolutions {
    fn next_revolution(&mut self) -> Option<LidarScan<'_>> {
        self.current = self.ranges.get(self.next)?.clone();
        self.next += 1;
        let geometry = LidarGeometry {
            first_angle: 0.0,
            angle_increment: core::f32::consts::TAU / self.current.len() as f32,
            ..GridSetup::EXAMPLE.lidar
        };
        Some(LidarScan::new(&self.current, geometry))
    }

    fn counters(&self) -> crate::wire::LidarCounters {
        crate::wire::LidarCounters {
            packets: self.next as u32,
            ..Default::default()
        }
    }
}

#[cfg(feature = "own-lidar")]
#[test]
fn the_devices_own_lidar_feeds_the_grid_estimator_as_scans_on_the_line_do() {
    use crate::grid::OccupancyGrid;
    use crate::pf::{GridPfConfig, GridSlam};
    type Slam<'g> = GridSlam<'g, 64, 64, 8, 40>;
    let config = GridPfConfig::MICROCONTROLLER;
    // A square room 2.4 m wide seen from its centre, 40 beams from 0°.
    let inc = core::f32::consts::TAU / 40.0;
    let room: std::vec::Vec<f32> = (0..40)
        .map(|i| {
            let a = inc * i as f32;
            1.2 / libm::fabsf(libm::cosf(a)).max(libm::fabsf(libm::sinf(a)))
        })
        .collect();
    let next = |seq: u32| ToDevice::Command {
        seq,
        command: Command::NextRevolution {
            stamp_us: u64::from(seq) * 1000,
        },
    };
    let select = ToDevice::Command {
        seq: 2,
        command: Command::SelectEstimator(EstimatorKind::Grid),
    };
    let bytes = frames(&[
        next(1),
        select,
        next(3),
        velocity(4, 0.1, 0.0),
        next(5),
        next(6),
        ToDevice::Command {
            seq: 7,
            command: Command::ReportStatus,
        },
    ]);

    let mut grid = OccupancyGrid::<64, 64>::centred(0.05, config.log_odds);
    let mut slam = Slam::new(&mut grid, config, Pose2::new(0.0, 0.0, 0.0)).unwrap();
    let mut lidar = Revolutions {
        ranges: std::vec![room.clone(); 3],
        next: 0,
        current: std::vec::Vec::new(),
    };
    let mut ekf = EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
    let mut session = Session::<_, _, 4>::with_grid(
        &mut ekf,
        EkfConfig::DEFAULT_F32,
        &mut slam,
        GridSetup::EXAMPLE,
    )
    .with_lidar(&mut lidar);
    let replies: std::vec::Vec<ToHost> = bytes.iter().filter_map(|&b| session.receive(b)).collect();
    drop(session);
    let revolution = |r: &ToHost| match *r {
        ToHost::Estimate(e) => (e.seq, e.stamp_us, e.estimator, e.result),
        ref other => panic!("{other:?}"),
    };
    // With the EKF active the revolution is read and skipped; then two go to the grid
    // filter; the fourth finds the lidar quiet.
    let (ekf_, grid_) = (EstimatorKind::Ekf, EstimatorKind::Grid);
    assert_eq!(
        revolution(&replies[0]),
        (1, 1000, ekf_, StepResult::Ignored)
    );
    assert_eq!(
        revolution(&replies[2]),
        (3, 3000, grid_, StepResult::Applied)
    );
    assert_eq!(
        revolution(&replies[4]),
        (5, 5000, grid_, StepResult::Applied)
    );
    let quiet = StepResult::Rejected {
        reason: LIDAR_FAILED,
    };
    assert_eq!(revolution(&replies[5]), (6, 6000, grid_, quiet));
    // The status carries the reader's counters (this lidar counts revolutions read).
    let ToHost::Status { lidar, .. } = replies[6] else {
        panic!("{:?}", replies[6])
    };
    assert_eq!(lidar.packets, 3);
    assert_eq!(replies.len(), 7);

    // The same scans straight into a filter of the same start: the same pose.
    let mut grid2 = OccupancyGrid::<64, 64>::centred(0.05, config.log_odds);
    let mut direct = Slam::new(&mut grid2, config, Pose2::new(0.0, 0.0, 0.0)).unwrap();
    let geometry = LidarGeometry {
        first_angle: 0.0,
        angle_increment: inc,
        ..GridSetup::EXAMPLE.lidar
    };
    direct.observe(&LidarScan::new(&room, geometry)).unwrap();
    direct.predict_velocity(0.1, 0.0, 0.1).unwrap();
    direct.observe(&LidarScan::new(&room, geometry)).unwrap();
    let p = direct.pose();
    assert_eq!(replies[4].estimate().unwrap().pose, [p.x, p.y, p.theta]);
}

#[test]
fn a_session_without_a_lidar_refuses_next_revolution() {
    let mut ekf = EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
    let mut session = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32);
    let bytes = frames(&[ToDevice::Command {
        seq: 7,
        command: Command::NextRevolution { stamp_us: 0 },
    }]);
    let replies: std::vec::Vec<ToHost> = bytes.iter().filter_map(|&b| session.receive(b)).collect();
    assert_eq!(
        replies,
        [ToHost::Refused {
            seq: 7,
            reason: Refusal::NoLidar,
            estimator: EstimatorKind::Ekf,
        }]
    );
}
