//! `stereonav fpga decode FILE`: the board's raw byte stream as JSON lines
//! (vehicle-interfaces.md section 5).

use std::fs::File;
use std::io::{self, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use fpga_link::{Decoder, Encoder, Event, Frame, Stats};
use harris_core::{Registers, detect};

use crate::harris::read_gray8;

/// Arguments of `stereonav fpga`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, clap::Subcommand)]
enum Command {
    /// Decode a raw byte stream: one JSON object a line per good packet
    /// (`{"frame", "t_us", "flags", "left": [[x_q4, y_q4, r], ...], "right": [...]}`), then a
    /// last line with the counters (`{"packets", "corrupt", "lost", "bytes_skipped"}`).
    Decode {
        /// The byte stream as received from the board (any file; `-` reads standard input).
        file: PathBuf,
    },
    /// Emulate the camera board: run its Harris detector on stereo image pairs (8-bit PGM or
    /// PNG) and write the packets it would send, one per pair, to OUT.
    Emulate {
        /// Where to write the byte stream.
        out: PathBuf,
        /// Image files, alternately left and right: LEFT RIGHT [LEFT RIGHT ...].
        #[arg(required = true, num_args = 2..)]
        images: Vec<PathBuf>,
        /// The `THRESHOLD` register.
        #[arg(long, default_value_t = harris_core::DEFAULT_THRESHOLD, allow_negative_numbers = true)]
        threshold: i32,
        /// The `MAX_FEATURES` register (1..=1023).
        #[arg(long, default_value_t = harris_core::DEFAULT_MAX_FEATURES)]
        max_features: usize,
        /// Timestamp of the first frame, microseconds.
        #[arg(long, default_value_t = 0)]
        t0_us: u64,
        /// Time between frames, microseconds (20 Hz by default).
        #[arg(long, default_value_t = 50_000)]
        period_us: u64,
        /// Frame counter of the first packet.
        #[arg(long, default_value_t = 0)]
        first_frame: u32,
    },
}

/// Bytes read from the file per decoder push.
const READ_CHUNK: usize = 1 << 16;

pub(crate) fn run(args: &Args) -> Result<()> {
    match &args.command {
        Command::Decode { file } => decode(file),
        Command::Emulate {
            out,
            images,
            threshold,
            max_features,
            t0_us,
            period_us,
            first_frame,
        } => {
            let regs = Registers {
                threshold: *threshold,
                max_features: *max_features,
                ..Registers::default()
            };
            emulate(out, images, regs, (*t0_us, *period_us), *first_frame)
        }
    }
}

fn decode(path: &Path) -> Result<()> {
    let name = path.display().to_string();
    let mut input: Box<dyn Read> = if name == "-" {
        Box::new(io::stdin().lock())
    } else {
        Box::new(File::open(path).with_context(|| format!("cannot open {name}"))?)
    };
    let mut out = BufWriter::new(io::stdout().lock());
    let mut decoder = Decoder::new();
    let mut chunk = vec![0u8; READ_CHUNK];
    loop {
        let n = match input.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e).with_context(|| format!("cannot read {name}")),
        };
        let mut rest = &chunk[..n];
        loop {
            let (used, event) = decoder.decode(rest);
            rest = &rest[used..];
            match event {
                Some(Event::Frame(frame)) => write_frame(&mut out, &frame)?,
                Some(Event::Corrupt(_)) => {}
                None => break,
            }
        }
    }
    while let Some(event) = decoder.decode_end() {
        if let Event::Frame(frame) = event {
            write_frame(&mut out, &frame)?;
        }
    }
    write_stats(&mut out, &decoder.stats())?;
    out.flush()?;
    Ok(())
}

/// Runs the board's detector on each image and writes one packet per stereo pair.
fn emulate(
    out: &Path,
    images: &[PathBuf],
    regs: Registers,
    (t0_us, period_us): (u64, u64),
    first_frame: u32,
) -> Result<()> {
    if !images.len().is_multiple_of(2) {
        bail!(
            "{} images given: pairs of LEFT RIGHT are needed",
            images.len()
        );
    }
    let mut encoder = Encoder::starting_at(first_frame);
    let mut stream = Vec::new();
    for (i, pair) in images.chunks_exact(2).enumerate() {
        let [left, right] = [&pair[0], &pair[1]].map(|path| -> Result<_> {
            let (width, height, pixels) = read_gray8(path)?;
            let regs = Registers {
                width,
                height,
                ..regs
            };
            detect(&pixels, &regs).with_context(|| path.display().to_string())
        });
        let (left, right) = (left?, right?);
        let t_us = t0_us.saturating_add(period_us.saturating_mul(i as u64));
        encoder
            .encode_to_vec(
                t_us,
                (&left.features, left.overflow),
                (&right.features, right.overflow),
                &mut stream,
            )
            .with_context(|| format!("pair {i}"))?;
    }
    std::fs::write(out, &stream).with_context(|| format!("cannot write {}", out.display()))
}

fn write_frame(out: &mut impl Write, frame: &Frame<'_>) -> io::Result<()> {
    write!(
        out,
        "{{\"frame\":{},\"t_us\":{},\"flags\":{},",
        frame.frame(),
        frame.t_us(),
        frame.flags()
    )?;
    for (key, features) in [("left", frame.left()), ("right", frame.right())] {
        write!(out, "\"{key}\":[")?;
        for (i, f) in features.enumerate() {
            let sep = if i == 0 { "" } else { "," };
            write!(out, "{sep}[{},{},{}]", f.x_q4, f.y_q4, f.r)?;
        }
        write!(out, "]{}", if key == "left" { "," } else { "" })?;
    }
    writeln!(out, "}}")
}

fn write_stats(out: &mut impl Write, stats: &Stats) -> io::Result<()> {
    writeln!(
        out,
        "{{\"packets\":{},\"corrupt\":{},\"lost\":{},\"bytes_skipped\":{}}}",
        stats.packets, stats.corrupt, stats.lost, stats.bytes_skipped
    )
}
