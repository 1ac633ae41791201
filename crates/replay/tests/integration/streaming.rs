//! The streaming replay: the files it writes as the frames come equal those written from the
//! whole [`Replay`]; a log whose frames reach it out of order (within the reorder window)
//! replays as the same log in order; a foreign or rig-less file is refused before any output
//! is made.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use replay::{NavSettings, OutputFiles, Replayer, replay_log};
use vehicle_log::{LogWriter, Record};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/logs")
        .join(name)
}

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("streaming");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// Every message of an MCAP file, `topic -> [(log time, data)]` sorted.
fn messages(path: &Path) -> BTreeMap<String, Vec<(u64, Vec<u8>)>> {
    let bytes = std::fs::read(path).unwrap();
    let mut out: BTreeMap<String, Vec<(u64, Vec<u8>)>> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        out.entry(m.channel.topic.clone())
            .or_default()
            .push((m.log_time, m.data.into_owned()));
    }
    for v in out.values_mut() {
        v.sort();
    }
    out
}

#[test]
fn streamed_outputs_equal_those_of_the_whole_replay() {
    for name in ["paper-experiment.mcap", "paper-square.mcap"] {
        let log = fixture(name);
        let settings = NavSettings::default();
        let whole = replay_log(&log, None, &settings, &mut |_, _| {}).unwrap();
        let (est_a, sum_a, traj_a) = (
            scratch(&format!("{name}.whole.est.mcap")),
            scratch(&format!("{name}.whole.json")),
            scratch(&format!("{name}.whole.csv")),
        );
        replay::write_estimates(&est_a, &whole).unwrap();
        replay::write_summary(&sum_a, &whole).unwrap();
        replay::write_trajectory(&traj_a, &whole).unwrap();

        let (est_b, sum_b, traj_b) = (
            scratch(&format!("{name}.stream.est.mcap")),
            scratch(&format!("{name}.stream.json")),
            scratch(&format!("{name}.stream.csv")),
        );
        let replayer = Replayer::open(&log, None, &settings).unwrap();
        let mut files = OutputFiles::create(Some(&est_b), Some(&traj_b)).unwrap();
        let mut seen = (0u64, 0u64);
        let end = replayer
            .run(&mut files, &mut |done, total| seen = (done, total))
            .unwrap();
        files.finish(&end, Some(&sum_b)).unwrap();

        let size = std::fs::metadata(&log).unwrap().len();
        assert_eq!(seen.1, size, "{name}: progress is in bytes of the file");
        assert!(seen.0 > 0 && seen.0 <= size, "{name}: {seen:?}");
        assert_eq!(end.frames_processed, whole.frames.len() as u64, "{name}");
        assert_eq!(end.last_frame.as_ref(), whole.frames.last(), "{name}");
        assert_eq!(
            std::fs::read_to_string(&sum_a).unwrap(),
            std::fs::read_to_string(&sum_b).unwrap(),
            "{name}: SUMMARY.json"
        );
        assert_eq!(
            std::fs::read_to_string(&traj_a).unwrap(),
            std::fs::read_to_string(&traj_b).unwrap(),
            "{name}: TRAJ.csv"
        );
        assert_eq!(messages(&est_a), messages(&est_b), "{name}: EST.mcap");
    }
}

/// The fixture's records, rewritten with the feature chunks `pick` chooses `delay_ns` late
/// in log order (so that odometry and truth of later instants come before them).
fn delayed_copy(name: &str, delay_ns: u64, pick: impl Fn(usize) -> bool, out: &Path) {
    let log = vehicle_log::read_log(fixture(name)).unwrap();
    let mut w = LogWriter::create(out).unwrap();
    // (log time, order, record): the chosen features moved later, everything else in place.
    let mut timed: Vec<(u64, usize, &Record)> = Vec::new();
    let mut chunk = 0;
    for (i, r) in log.records.iter().enumerate() {
        match r {
            Record::Rig(text) => w.rig_json(text).unwrap(),
            Record::TruthLandmarks(l) => w.truth_landmarks(l).unwrap(),
            Record::TruthCamera(c) => w.truth_camera(c).unwrap(),
            Record::Features { log_time_ns, .. } => {
                let delay = if pick(chunk) { delay_ns } else { 0 };
                chunk += 1;
                timed.push((log_time_ns + delay, i, r));
            }
            Record::Odom(s) => timed.push((s.t_us * 1000, i, r)),
            Record::TruthPose(p) => timed.push((p.t_us * 1000, i, r)),
            _ => {}
        }
    }
    timed.sort_by_key(|(t, i, _)| (*t, *i));
    for (t, _, r) in timed {
        match r {
            Record::Features { bytes, .. } => w.features(t, bytes).unwrap(),
            Record::Odom(s) => w.odom(s).unwrap(),
            Record::TruthPose(p) => w.truth_pose(p).unwrap(),
            _ => {}
        }
    }
    w.finish().unwrap();
}

fn reference() -> replay::Replay {
    replay_log(
        fixture("paper-experiment.mcap"),
        None,
        &NavSettings::default(),
        &mut |_, _| {},
    )
    .unwrap()
}

#[test]
fn frames_that_reach_the_log_late_replay_as_in_order() {
    let reference = reference();
    // Every frame 1.5 s or 5 s late (a slow link): the frames' own order is kept, and the
    // odometry before them waits in the window; the replay is the same.
    for delay_s in [1.5, 5.0] {
        let late = scratch(&format!("late-{delay_s}s.mcap"));
        delayed_copy(
            "paper-experiment.mcap",
            (delay_s * 1e9) as u64,
            |_| true,
            &late,
        );
        let r = replay_log(&late, None, &NavSettings::default(), &mut |_, _| {}).unwrap();
        assert_eq!(r.frames, reference.frames, "{delay_s} s");
        assert_eq!(r.landmarks, reference.landmarks, "{delay_s} s");
        assert_eq!(r.final_camera, reference.final_camera, "{delay_s} s");
    }
    // Every other chunk 1.5 s late (out of order among themselves, inside the window): the
    // board stream's packets that straddle the moved chunks are lost, the rest in order.
    let shuffled = scratch("late-every-other.mcap");
    delayed_copy(
        "paper-experiment.mcap",
        1_500_000_000,
        |i| i % 2 == 1,
        &shuffled,
    );
    let r = replay_log(&shuffled, None, &NavSettings::default(), &mut |_, _| {}).unwrap();
    assert!(r.frames.windows(2).all(|w| w[0].t_us <= w[1].t_us));
    assert!(
        !r.warnings.iter().any(|w| w.contains("out of order")),
        "{:?}",
        r.warnings
    );
}

#[test]
fn a_chunk_later_than_the_window_is_refused_and_counted() {
    let reference = reference();
    // One chunk in the middle 5 s late: its frames come after later ones have gone to the
    // navigator, which refuses them (counted in one warning); the rest replays.
    let late = scratch("late-one-chunk.mcap");
    delayed_copy("paper-experiment.mcap", 5_000_000_000, |i| i == 500, &late);
    let r = replay_log(&late, None, &NavSettings::default(), &mut |_, _| {}).unwrap();
    assert!(
        r.frames.len() + 20 >= reference.frames.len(),
        "{}",
        r.frames.len()
    );
    let refusals: Vec<&String> = r
        .warnings
        .iter()
        .filter(|w| w.contains("refused by the navigator"))
        .collect();
    assert!(refusals.len() <= 1, "{refusals:?}");
    let t = r.truth.as_ref().unwrap();
    assert!(t.landmark_rms < 0.01, "{t:?}");
}

#[test]
fn a_foreign_file_is_refused_before_any_output() {
    let foreign = scratch("foreign.mcap");
    {
        let mut w = mcap::Writer::new(std::io::BufWriter::new(
            std::fs::File::create(&foreign).unwrap(),
        ))
        .unwrap();
        let ch = w
            .add_channel(0, "/camera/image", "cdr", &Default::default())
            .unwrap();
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: ch,
                sequence: 0,
                log_time: 1,
                publish_time: 1,
            },
            b"abc",
        )
        .unwrap();
        w.finish().unwrap();
    }
    let err = Replayer::open(&foreign, None, &NavSettings::default()).unwrap_err();
    assert!(
        err.to_string().contains("is not a vehicle log")
            && err.to_string().contains("/camera/image"),
        "{err}"
    );
}

#[test]
fn a_log_without_a_rig_is_refused_unless_one_is_given() {
    let log = vehicle_log::read_log(fixture("paper-experiment.mcap")).unwrap();
    let path = scratch("no-rig.mcap");
    let mut w = LogWriter::create(&path).unwrap();
    let mut rig_text = None;
    for r in &log.records {
        match r {
            Record::Rig(text) => rig_text = Some(text.clone()),
            Record::Features { log_time_ns, bytes } => w.features(*log_time_ns, bytes).unwrap(),
            Record::Odom(s) => w.odom(s).unwrap(),
            _ => {}
        }
    }
    w.finish().unwrap();
    let err = Replayer::open(&path, None, &NavSettings::default()).unwrap_err();
    assert!(err.to_string().contains("no rig"), "{err}");
    let rig = rig_model::Rig::from_json_str(&rig_text.unwrap(), "rig").unwrap();
    let r = replay_log(&path, Some(rig), &NavSettings::default(), &mut |_, _| {}).unwrap();
    assert!(r.frames.len() > 900, "{}", r.frames.len());
}
