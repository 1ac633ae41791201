//! `stereonav log check LOG [--left T --right T --odom T] [--rig RIG] [--json]` and
//! `stereonav log recover IN OUT`: what is damaged in a vehicle log (vehicle-interfaces.md
//! section 4) or a ROS 2 bag (4.1) and what a replay will use of it, and a clean copy of
//! everything that can still be read (`vehicle_log::recover`).
//!
//! Of a ROS 2 bag without topics named, the check lists the camera and odometry topics a
//! replay could be given; with them named, it reads those topics as the replay does (each
//! message decoded by its schema, the images paired by stamp) and reports the images per
//! camera (encodings or formats, sizes, rate), the stereo frames and lone images, and the
//! odometry; with `--rig`, images of another size than its `[camera]` are counted.
//!
//! Reports go to stdout; a progress bar by bytes is drawn on stderr when it is a terminal and
//! the file is big. `log check` exits 0 for an undamaged log and 1 for a damaged one; a file
//! that cannot be read or is not MCAP is a one-line error (exit 1) as everywhere.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Result;
use serde_json::{Value, json};
use vehicle_log::{
    CameraImage, Damage, LogReader, LostSpan, Record, Role, Side, SummaryState, topics,
};

use crate::progress::ByteProgress;

/// Arguments of `stereonav log`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, clap::Subcommand)]
enum Command {
    /// Check a vehicle log: print what is damaged, where (file offsets, log-time spans), and
    /// what a replay will use (messages read and lost per vehicle topic). Exit status 0 for
    /// an undamaged log, 1 for a damaged one.
    Check {
        /// The vehicle log (MCAP).
        #[arg(value_name = "LOG.mcap")]
        log: PathBuf,
        #[command(flatten)]
        topics: crate::topics::TopicArgs,
        /// With the topics named: the rig file whose `[camera]` size the images must have.
        #[arg(long, value_name = "RIG.toml")]
        rig: Option<PathBuf>,
        /// Print the report as one JSON object instead.
        #[arg(long)]
        json: bool,
    },
    /// Recover a damaged log: write every readable schema, channel and message (any topic,
    /// with its times, in order) to OUT as a clean MCAP file (zstd chunks, summary), and print
    /// what was dropped.
    Recover {
        /// The damaged log (MCAP).
        #[arg(value_name = "IN.mcap")]
        input: PathBuf,
        /// Where to write the clean log (not IN).
        #[arg(value_name = "OUT.mcap")]
        output: PathBuf,
    },
}

/// Records between two updates of the progress bar.
const PROGRESS_EVERY: u64 = 4096;

/// Lost spans listed one a line in the text report (the JSON report has all that are kept).
const SPANS_SHOWN: usize = 20;

pub(crate) fn run(args: &Args) -> Result<ExitCode> {
    match &args.command {
        Command::Check {
            log,
            topics,
            rig,
            json,
        } => check(log, topics, rig.as_deref(), *json),
        Command::Recover { input, output } => recover(input, output),
    }
}

/// What the reading of a log gave, for the report.
struct Checked {
    damage: Damage,
    /// Per vehicle topic: messages read.
    read: Vec<(&'static str, u64)>,
    /// Vehicle topics with a channel in the log.
    topics: Vec<&'static str>,
    ignored_messages: u64,
    ignored_topics: Vec<String>,
    warnings: Vec<String>,
    truncated: Option<String>,
    file_len: u64,
    /// A ROS 2 bag's camera and odometry topics: `(topic, type, messages)`.
    bag_topics: Vec<(String, String, u64)>,
    /// The named topics' report, when named.
    bag: Option<BagCheck>,
}

/// What the named topics of a ROS 2 bag hold.
#[derive(Default)]
struct BagCheck {
    /// Per camera (left, right): the topic, its type and what its images are.
    cameras: [CameraCheck; 2],
    /// The odometry topic, its type, samples and first and last stamps, us.
    odom: (String, String, u64, Option<(u64, u64)>),
    /// Stereo frames paired and images without a partner.
    frames: u64,
    unpaired: u64,
    /// The frame interval the pairing used, us.
    interval_us: Option<u64>,
}

#[derive(Default)]
struct CameraCheck {
    topic: String,
    ty: String,
    images: u64,
    /// `(what it is, width, height)` -> images.
    kinds: BTreeMap<(String, u32, u32), u64>,
    /// Images that do not decode (message or header), of another size than the rig's.
    undecodable: u64,
    wrong_size: u64,
    first_problem: Option<String>,
    stamps: Option<(u64, u64)>,
}

impl CameraCheck {
    fn image(&mut self, image: &CameraImage, size: Option<(u32, u32)>) {
        self.images += 1;
        let (a, b) = self.stamps.unwrap_or((image.t_us, image.t_us));
        self.stamps = Some((a.min(image.t_us), b.max(image.t_us)));
        match host_board::gray::describe(&image.payload) {
            Ok((w, h, kind)) => {
                *self.kinds.entry((kind, w, h)).or_default() += 1;
                if size.is_some_and(|s| s != (w, h)) {
                    self.wrong_size += 1;
                }
            }
            Err(e) => self.bad(e.to_string()),
        }
    }

    fn bad(&mut self, problem: String) {
        self.undecodable += 1;
        self.first_problem.get_or_insert(problem);
    }
}

fn check(
    path: &Path,
    topics: &crate::topics::TopicArgs,
    rig: Option<&Path>,
    as_json: bool,
) -> Result<ExitCode> {
    let mut reader = LogReader::open(path)?;
    let named = topics.topics();
    let size = rig
        .map(rig_model::Rig::load)
        .transpose()?
        .map(|r| (r.width, r.height));
    let mut bag = named.as_ref().map(|t| {
        let mut b = BagCheck::default();
        b.cameras[0].topic.clone_from(&t.left);
        b.cameras[1].topic.clone_from(&t.right);
        b.odom.0.clone_from(&t.odom);
        b
    });
    let mut pairer = host_board::Pairer::new();
    if let Some(t) = named {
        reader.set_ros2_topics(t);
    }
    let mut bar = ByteProgress::new("checking");
    let mut records = 0u64;
    while let Some(record) = reader.next() {
        let record = record?;
        if let Some(b) = bag.as_mut() {
            bag_record(b, &mut pairer, record, size);
        }
        records += 1;
        if records.is_multiple_of(PROGRESS_EVERY) {
            bar.update(reader.position(), reader.file_len());
        }
    }
    bar.finish();
    let checked = Checked {
        damage: reader.damage().clone(),
        read: reader.messages_read(),
        topics: reader.topics().to_vec(),
        ignored_messages: reader.ignored_messages(),
        ignored_topics: reader.ignored_topics().to_vec(),
        warnings: reader.warnings().to_vec(),
        truncated: reader.truncated().map(str::to_owned),
        file_len: reader.file_len(),
        bag_topics: bag_topics(&reader),
        bag: bag.map(|mut b| {
            pairer.end();
            drain_pairs(&mut b, &mut pairer);
            b.interval_us = pairer.interval_us();
            for (role, ty) in reader.ros2_met() {
                match role {
                    Role::Left => b.cameras[0].ty.clone_from(ty),
                    Role::Right => b.cameras[1].ty.clone_from(ty),
                    Role::Odom => b.odom.1.clone_from(ty),
                }
            }
            b
        }),
    };
    let text = if as_json {
        let mut s = serde_json::to_string_pretty(&check_json(path, &checked))?;
        s.push('\n');
        s
    } else {
        check_text(path, &checked)
    };
    io::stdout().lock().write_all(text.as_bytes())?;
    Ok(if checked.damage.is_clean() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

/// A record of a bag whose topics were named, into the report.
fn bag_record(
    b: &mut BagCheck,
    pairer: &mut host_board::Pairer,
    record: Record,
    size: Option<(u32, u32)>,
) {
    match record {
        Record::Image(image) => {
            let side = image.side;
            b.cameras[usize::from(side == Side::Right)].image(&image, size);
            match side {
                Side::Left => pairer.push_left(image),
                Side::Right => pairer.push_right(image),
            }
            drain_pairs(b, pairer);
        }
        Record::BadImage { side, problem, .. } => {
            let camera = &mut b.cameras[usize::from(side == Side::Right)];
            camera.images += 1;
            camera.bad(problem);
        }
        Record::Odom(s) => {
            b.odom.2 += 1;
            let (a, z) = b.odom.3.unwrap_or((s.t_us, s.t_us));
            b.odom.3 = Some((a.min(s.t_us), z.max(s.t_us)));
        }
        _ => {}
    }
}

fn drain_pairs(b: &mut BagCheck, pairer: &mut host_board::Pairer) {
    while let Some(p) = pairer.pop() {
        match p {
            host_board::Paired::Frame { .. } => b.frames += 1,
            host_board::Paired::Alone(_) => b.unpaired += 1,
        }
    }
}

/// A ROS 2 bag's camera and odometry topics among the foreign ones: `(topic, type, messages)`.
fn bag_topics<R>(reader: &LogReader<R>) -> Vec<(String, String, u64)> {
    reader
        .foreign_channels()
        .iter()
        .zip(reader.foreign_messages())
        .filter(|((_, ty), _)| {
            let t = vehicle_log::ros2::msgdef::normalise_type_name(ty);
            t == "sensor_msgs/Image"
                || t == "sensor_msgs/CompressedImage"
                || t == "nav_msgs/Odometry"
        })
        .map(|((topic, ty), n)| (topic.clone(), ty.clone(), *n))
        .collect()
}

fn rate_hz(n: u64, stamps: Option<(u64, u64)>) -> f64 {
    match stamps {
        Some((a, b)) if b > a && n > 1 => (n - 1) as f64 / ((b - a) as f64 * 1e-6),
        _ => 0.0,
    }
}

/// The named topics' lines of the text report.
fn bag_lines(b: &BagCheck) -> Vec<String> {
    let mut lines = Vec::new();
    for (camera, name) in b.cameras.iter().zip(["left camera", "right camera"]) {
        let kinds: Vec<String> = camera
            .kinds
            .iter()
            .map(|((kind, w, h), n)| format!("{n} {kind} {w}x{h}"))
            .collect();
        let mut line = format!(
            "{} ({name}, {}): {} images ({}), {:.1} Hz",
            camera.topic,
            if camera.ty.is_empty() {
                "no such topic"
            } else {
                &camera.ty
            },
            camera.images,
            if kinds.is_empty() {
                "none readable".to_owned()
            } else {
                kinds.join(", ")
            },
            rate_hz(camera.images, camera.stamps)
        );
        if camera.wrong_size > 0 {
            let _ = write!(
                line,
                "; {} of another size than the rig's",
                camera.wrong_size
            );
        }
        if camera.undecodable > 0 {
            let _ = write!(
                line,
                "; {} undecodable, the first: {}",
                camera.undecodable,
                camera.first_problem.as_deref().unwrap_or_default()
            );
        }
        lines.push(line);
    }
    let (topic, ty, n, stamps) = &b.odom;
    lines.push(format!(
        "{topic} (odometry, {}): {n} samples, {:.1} Hz",
        if ty.is_empty() { "no such topic" } else { ty },
        rate_hz(*n, *stamps)
    ));
    lines.push(format!(
        "stereo frames: {} (stamps within a quarter of the {} frame interval), {} images without a partner",
        b.frames,
        b.interval_us.map_or("unknown".to_owned(), |i| format!("{:.1} ms", i as f64 * 1e-3)),
        b.unpaired
    ));
    lines
}

fn bag_json(b: &BagCheck) -> Value {
    let camera = |c: &CameraCheck| {
        json!({
            "topic": c.topic,
            "type": c.ty,
            "images": c.images,
            "kinds": c.kinds.iter().map(|((kind, w, h), n)| json!({"kind": kind, "width": w, "height": h, "images": n})).collect::<Vec<_>>(),
            "wrong_size": c.wrong_size,
            "undecodable": c.undecodable,
            "first_problem": c.first_problem,
            "rate_hz": rate_hz(c.images, c.stamps),
        })
    };
    json!({
        "left": camera(&b.cameras[0]),
        "right": camera(&b.cameras[1]),
        "odom": {"topic": b.odom.0, "type": b.odom.1, "samples": b.odom.2, "rate_hz": rate_hz(b.odom.2, b.odom.3)},
        "frames": b.frames,
        "unpaired": b.unpaired,
        "interval_us": b.interval_us,
    })
}

/// The vehicle topics a replay reads, in the report's order.
const REPORTED_TOPICS: [&str; 6] = [
    topics::FEATURES,
    topics::ODOM,
    topics::RIG,
    topics::TRUTH_POSE,
    topics::TRUTH_LANDMARKS,
    topics::TRUTH_CAMERA,
];

/// Per vehicle topic with a channel or messages: `(topic, read, lost when known)`.
fn topic_rows(c: &Checked) -> Vec<(&'static str, u64, Option<u64>)> {
    REPORTED_TOPICS
        .iter()
        .filter_map(|&topic| {
            let read = c
                .read
                .iter()
                .find(|(t, _)| *t == topic)
                .map_or(0, |(_, n)| *n);
            let lost = c
                .damage
                .messages_lost
                .as_ref()
                .map(|m| m.get(topic).copied().unwrap_or(0));
            (c.topics.contains(&topic) || read > 0 || lost.is_some_and(|n| n > 0))
                .then_some((topic, read, lost))
        })
        .collect()
}

fn check_text(path: &Path, c: &Checked) -> String {
    let mut s = String::new();
    let verdict = if c.damage.is_clean() {
        "no damage found"
    } else {
        "DAMAGED"
    };
    let _ = writeln!(s, "{}: {verdict} ({} bytes)", path.display(), c.file_len);
    for line in damage_lines(&c.damage) {
        let _ = writeln!(s, "  {line}");
    }
    if let Some(why) = &c.truncated {
        let _ = writeln!(s, "  {why}");
    }
    let _ = writeln!(s, "what a replay will use:");
    let rows = topic_rows(c);
    if let Some(b) = &c.bag {
        for line in bag_lines(b) {
            let _ = writeln!(s, "  {line}");
        }
    } else if !c.bag_topics.is_empty() && rows.is_empty() {
        let _ = writeln!(
            s,
            "  a ROS 2 bag: name its camera and odometry topics with --left, --right and --odom; it has:"
        );
        for (topic, ty, n) in &c.bag_topics {
            let _ = writeln!(s, "    {topic} ({ty}): {n} messages");
        }
    }
    if rows.is_empty() && c.bag.is_none() && c.bag_topics.is_empty() {
        let _ = writeln!(
            s,
            "  nothing: no vehicle topic (a replay refuses the log); topics: {}",
            if c.ignored_topics.is_empty() {
                "none".to_owned()
            } else {
                c.ignored_topics.join(", ")
            }
        );
    }
    for (topic, read, lost) in rows {
        let lost = lost.map_or("an unknown number".to_owned(), |n| n.to_string());
        let _ = writeln!(s, "  {topic}: {read} messages read, {lost} lost");
    }
    if c.ignored_messages > 0 {
        let _ = writeln!(
            s,
            "  ignored: {} messages on other topics ({})",
            c.ignored_messages,
            c.ignored_topics.join(", ")
        );
    }
    for w in &c.warnings {
        if !w.starts_with("the log is damaged") {
            let _ = writeln!(s, "  warning: {w}");
        }
    }
    s
}

/// The damage, a line each: header, summary, cut, each lost span (the first
/// [`SPANS_SHOWN`]), chunks read without a CRC.
fn damage_lines(d: &Damage) -> Vec<String> {
    let mut lines = Vec::new();
    if d.header_damaged {
        lines.push(
            "the magic or header record at the start is damaged (the file was read past it)"
                .to_owned(),
        );
    }
    match &d.summary {
        SummaryState::Intact => lines.push(
            "summary section intact: its schemas, channels, chunk index and statistics were used"
                .to_owned(),
        ),
        SummaryState::Damaged { why } => {
            lines.push(format!("summary section damaged, not used: {why}"))
        }
        SummaryState::Absent if d.cut => {
            lines.push("no summary section: the file is cut before it".to_owned());
        }
        _ => lines.push("no summary section (its writer wrote none)".to_owned()),
    }
    if d.tail_damaged {
        lines.push("the closing magic is damaged".to_owned());
    }
    if d.spans_total > 0 {
        lines.push(format!(
            "lost: {} spans, {} bytes, {} chunks",
            d.spans_total, d.bytes_lost, d.chunks_lost
        ));
    }
    for span in d.spans.iter().take(SPANS_SHOWN) {
        lines.push(format!("  {}", span_line(span)));
    }
    let more = d
        .spans_total
        .saturating_sub(SPANS_SHOWN.min(d.spans.len()) as u64);
    if more > 0 {
        lines.push(format!("  ... and {more} more"));
    }
    if d.repaired_chunks > 0 {
        lines.push(format!(
            "mended {} chunks: one flipped bit explained each one's damage, and its CRC checks \
             after the mend (used whole, nothing lost)",
            d.repaired_chunks
        ));
    }
    if d.unverified_chunks > 0 {
        lines.push(format!(
            "{} chunks read without a CRC check (cut by the end of the file, or written \
             without a CRC)",
            d.unverified_chunks
        ));
    }
    lines
}

fn seconds(ns: Option<u64>) -> String {
    ns.map_or("?".to_owned(), |ns| format!("{:.3}", ns as f64 * 1e-9))
}

fn span_line(span: &LostSpan) -> String {
    let times = if span.exact_times {
        format!(
            "log time {}..{} s",
            seconds(span.start_ns),
            seconds(span.end_ns)
        )
    } else {
        format!(
            "log time between {} s and {} s",
            seconds(span.start_ns),
            seconds(span.end_ns)
        )
    };
    let messages = match &span.messages {
        Some(m) if m.is_empty() => "no messages lost".to_owned(),
        Some(m) => format!(
            "lost {}",
            m.iter()
                .map(|(t, n)| format!("{t} {n}"))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        None => "messages lost: unknown".to_owned(),
    };
    format!(
        "offset {} ({} bytes), {times}: {}; {messages}",
        span.offset, span.bytes, span.why
    )
}

fn span_json(span: &LostSpan) -> Value {
    json!({
        "offset": span.offset,
        "bytes": span.bytes,
        "start_ns": span.start_ns,
        "end_ns": span.end_ns,
        "exact_times": span.exact_times,
        "chunks": span.chunks,
        "messages": span.messages,
        "why": span.why,
    })
}

fn damage_json(d: &Damage) -> Value {
    let (summary, summary_problem) = match &d.summary {
        SummaryState::Intact => ("intact", None),
        SummaryState::Damaged { why } => ("damaged", Some(why.as_str())),
        _ => ("absent", None),
    };
    json!({
        "damaged": !d.is_clean(),
        "header_damaged": d.header_damaged,
        "tail_damaged": d.tail_damaged,
        "cut": d.cut,
        "summary": summary,
        "summary_problem": summary_problem,
        "spans_total": d.spans_total,
        "bytes_lost": d.bytes_lost,
        "chunks_lost": d.chunks_lost,
        "unverified_chunks": d.unverified_chunks,
        "repaired_chunks": d.repaired_chunks,
        "messages_lost": d.messages_lost,
        "spans": d.spans.iter().map(span_json).collect::<Vec<_>>(),
    })
}

fn check_json(path: &Path, c: &Checked) -> Value {
    let topics: BTreeMap<&str, Value> = topic_rows(c)
        .into_iter()
        .map(|(t, read, lost)| (t, json!({"read": read, "lost": lost})))
        .collect();
    json!({
        "path": path.display().to_string(),
        "bytes": c.file_len,
        "damage": damage_json(&c.damage),
        "truncated": c.truncated,
        "topics": topics,
        "ignored_messages": c.ignored_messages,
        "ignored_topics": c.ignored_topics,
        "warnings": c.warnings,
        "ros2": c.bag.as_ref().map(bag_json),
        "ros2_topics": c.bag_topics.iter().map(|(t, ty, n)| json!({"topic": t, "type": ty, "messages": n})).collect::<Vec<_>>(),
    })
}

fn recover(input: &Path, output: &Path) -> Result<ExitCode> {
    let mut bar = ByteProgress::new("recovering");
    let result = vehicle_log::recover(input, output, &mut |done, total| bar.update(done, total));
    bar.finish();
    let r = result?;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{}: {} schemas, {} channels, {} messages recovered from {}",
        output.display(),
        r.schemas,
        r.channels,
        r.messages,
        input.display()
    );
    for (topic, n) in &r.messages_per_topic {
        let _ = writeln!(s, "  {topic}: {n} messages");
    }
    if r.damage.is_clean() {
        let _ = writeln!(s, "dropped: nothing ({} had no damage)", input.display());
    } else {
        let _ = writeln!(s, "dropped:");
        for line in damage_lines(&r.damage) {
            let _ = writeln!(s, "  {line}");
        }
        match &r.damage.messages_lost {
            Some(lost) if !lost.is_empty() => {
                let per_topic: Vec<String> = lost.iter().map(|(t, n)| format!("{t} {n}")).collect();
                let _ = writeln!(s, "  messages lost: {}", per_topic.join(", "));
            }
            Some(_) => {}
            None => {
                let _ = writeln!(s, "  messages lost: unknown (nothing counts them)");
            }
        }
    }
    if r.undeclared > 0 {
        let _ = writeln!(
            s,
            "  {} messages on channels whose channel record was lost: not written",
            r.undeclared
        );
    }
    for topic in &r.schemaless {
        let _ = writeln!(
            s,
            "  channel {topic}: its schema was lost: written without a schema"
        );
    }
    io::stdout().lock().write_all(s.as_bytes())?;
    Ok(ExitCode::SUCCESS)
}
