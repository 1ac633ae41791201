//! `stereonav fpga decode FILE`: the board's raw byte stream as JSON lines
//! (vehicle-interfaces.md section 5).

use std::fs::File;
use std::io::{self, BufWriter, Read, Write};
use std::path::PathBuf;

use anyhow::{Context, Result};
use fpga_link::{Decoder, Event, Frame, Stats};

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
}

/// Bytes read from the file per decoder push.
const READ_CHUNK: usize = 1 << 16;

pub(crate) fn run(args: &Args) -> Result<()> {
    match &args.command {
        Command::Decode { file } => decode(file),
    }
}

fn decode(path: &PathBuf) -> Result<()> {
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
