//! The replay's output files (vehicle-interfaces.md section 5): `EST.mcap` for a viewer (the
//! `estimates-log` crate writes it), `SUMMARY.json` and `TRAJ.csv`, and the trajectory and the
//! log's truth as TUM files for evo ([`crate::TumWriter`]).
//!
//! `SUMMARY.json` is [`summary_json`] (the `/est/summary` message of `EST.mcap`),
//! pretty-printed. `TRAJ.csv` prints numbers that are not finite as `NaN`, `inf` or `-inf`
//! (Rust's `f64` display, which `str::parse::<f64>` reads back).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use estimates_log::{EstimatesWriter, end_summary_json, summary_json};
use serde_json::Value;

use crate::{CameraSample, Error, FrameEstimate, MapSnapshot, Replay, ReplayEnd, TumWriter};

/// What `SUMMARY.json` is called in error messages.
const SUMMARY_FILE: &str = "SUMMARY.json";
/// What `TRAJ.csv` is called in error messages.
const TRAJ_FILE: &str = "TRAJ.csv";

/// Writes `EST.mcap` at `path`: [`estimates_log::write_estimates`], its errors as the
/// replay's.
///
/// Errors: the file cannot be created or written ([`Error::Output`]), the MCAP writer refuses
/// a record ([`Error::Mcap`]), or a timestamp is too late for a Foxglove timestamp
/// ([`Error::TimeOutOfRange`], found before the file is created). A file left by an error is
/// incomplete.
pub fn write_estimates(path: &Path, replay: &Replay) -> Result<(), Error> {
    Ok(estimates_log::write_estimates(path, replay)?)
}

/// Writes `SUMMARY.json` at `path`: [`summary_json`], pretty-printed, with a final newline.
///
/// Errors: the file cannot be created or written ([`Error::Output`]).
pub fn write_summary(path: &Path, replay: &Replay) -> Result<(), Error> {
    write_summary_value(path, &summary_json(replay))
}

/// Writes a summary (from [`summary_json`] or [`end_summary_json`]) at `path`,
/// pretty-printed, with a final newline.
///
/// Errors: the file cannot be created or written ([`Error::Output`]).
pub fn write_summary_value(path: &Path, summary: &Value) -> Result<(), Error> {
    let write = || -> std::io::Result<()> {
        let mut w = BufWriter::new(File::create(path)?);
        serde_json::to_writer_pretty(&mut w, summary)?;
        w.write_all(b"\n")?;
        w.flush()
    };
    write().map_err(|source| output_error(SUMMARY_FILE, path, source))
}

/// Writes `TRAJ.csv` at `path`: a header `t_us,x,y,theta` and a row per frame of `replay`, in
/// its order ([`TrajectoryWriter`]).
///
/// Errors: the file cannot be created or written ([`Error::Output`]).
pub fn write_trajectory(path: &Path, replay: &Replay) -> Result<(), Error> {
    let mut w = TrajectoryWriter::create(path)?;
    for frame in &replay.frames {
        w.frame(frame)?;
    }
    w.finish()
}

/// Writes the trajectory of `replay` as a TUM file at `path` (a pose per frame, in its
/// order; [`TumWriter`]), as `stereonav replay --trajectory-tum` does while streaming.
///
/// Errors: the file cannot be created or written ([`Error::Output`]).
pub fn write_trajectory_tum(path: &Path, replay: &Replay) -> Result<(), Error> {
    let mut w = TumWriter::create(TRAJ_TUM_FILE, path)?;
    for frame in &replay.frames {
        w.pose(frame.t_us, frame.pose)?;
    }
    w.finish()
}

/// Writes `TRAJ.csv` row by row: a header `t_us,x,y,theta`, then a row per frame. Numbers
/// are printed with Rust's `Display`, which reads back to the same `f64`.
#[derive(Debug)]
pub struct TrajectoryWriter {
    path: PathBuf,
    w: BufWriter<File>,
}

impl TrajectoryWriter {
    /// Creates (or truncates) the file at `path` and writes the header.
    ///
    /// Errors: the file cannot be created or written ([`Error::Output`]).
    pub fn create(path: &Path) -> Result<Self, Error> {
        let mut w = BufWriter::new(
            File::create(path).map_err(|source| output_error(TRAJ_FILE, path, source))?,
        );
        writeln!(w, "t_us,x,y,theta").map_err(|source| output_error(TRAJ_FILE, path, source))?;
        Ok(Self {
            path: path.to_path_buf(),
            w,
        })
    }

    /// A frame's row.
    pub fn frame(&mut self, frame: &FrameEstimate) -> Result<(), Error> {
        let [x, y, theta] = frame.pose;
        writeln!(self.w, "{},{x},{y},{theta}", frame.t_us)
            .map_err(|source| output_error(TRAJ_FILE, &self.path, source))
    }

    /// Flushes the file.
    pub fn finish(mut self) -> Result<(), Error> {
        self.w
            .flush()
            .map_err(|source| output_error(TRAJ_FILE, &self.path, source))
    }
}

/// What the TUM trajectory (`--trajectory-tum`) is called in error messages.
pub const TRAJ_TUM_FILE: &str = "TRAJ.tum";
/// What the TUM truth (`--truth-tum`) is called in error messages.
pub const TRUTH_TUM_FILE: &str = "TRUTH.tum";

/// The replay's output files written as the frames come (a [`crate::ReplaySink`]):
/// `EST.mcap` and `TRAJ.csv` when asked for, the TUM files when added
/// ([`OutputFiles::with_tum`]); [`OutputFiles::finish`] adds the summary.
#[derive(Debug, Default)]
pub struct OutputFiles {
    estimates: Option<EstimatesWriter>,
    trajectory: Option<TrajectoryWriter>,
    trajectory_tum: Option<TumWriter>,
    truth_tum: Option<TumWriter>,
}

impl OutputFiles {
    /// Creates the files asked for.
    ///
    /// Errors: a file cannot be created ([`Error::Output`], [`Error::Mcap`]).
    pub fn create(estimates: Option<&Path>, trajectory: Option<&Path>) -> Result<Self, Error> {
        Ok(Self {
            estimates: estimates.map(EstimatesWriter::create).transpose()?,
            trajectory: trajectory.map(TrajectoryWriter::create).transpose()?,
            trajectory_tum: None,
            truth_tum: None,
        })
    }

    /// Adds the TUM files asked for: the trajectory (a pose per frame, every frame the
    /// summary's `truth.ate_rms_m` is over when the log has truth) and the log's true pose at
    /// those frames (only frames with a true pose), so that `evo_ape tum TRUTH TRAJ` compares
    /// what the project's ATE compares.
    ///
    /// Errors: a file cannot be created ([`Error::Output`]).
    pub fn with_tum(
        mut self,
        trajectory: Option<&Path>,
        truth: Option<&Path>,
    ) -> Result<Self, Error> {
        self.trajectory_tum = trajectory
            .map(|p| TumWriter::create(TRAJ_TUM_FILE, p))
            .transpose()?;
        self.truth_tum = truth
            .map(|p| TumWriter::create(TRUTH_TUM_FILE, p))
            .transpose()?;
        Ok(self)
    }

    /// Ends the files: `EST.mcap` with its `/est/summary` message, and `SUMMARY.json` at
    /// `summary` when asked for.
    pub fn finish(self, end: &ReplayEnd, summary: Option<&Path>) -> Result<(), Error> {
        let value = end_summary_json(end);
        if let Some(w) = self.estimates {
            w.finish(&value)?;
        }
        if let Some(w) = self.trajectory {
            w.finish()?;
        }
        for w in [self.trajectory_tum, self.truth_tum].into_iter().flatten() {
            w.finish()?;
        }
        if let Some(path) = summary {
            write_summary_value(path, &value)?;
        }
        Ok(())
    }
}

impl crate::ReplaySink for OutputFiles {
    fn frame(&mut self, frame: &FrameEstimate) -> Result<(), Error> {
        if let Some(w) = &mut self.estimates {
            w.frame(frame)?;
        }
        if let Some(w) = &mut self.trajectory {
            w.frame(frame)?;
        }
        if let Some(w) = &mut self.trajectory_tum {
            w.pose(frame.t_us, frame.pose)?;
        }
        Ok(())
    }

    fn truth(&mut self, t_us: u64, pose: [f64; 3]) -> Result<(), Error> {
        match &mut self.truth_tum {
            Some(w) => w.pose(t_us, pose),
            None => Ok(()),
        }
    }

    fn camera(&mut self, sample: &CameraSample) -> Result<(), Error> {
        match &mut self.estimates {
            Some(w) => Ok(w.camera(sample)?),
            None => Ok(()),
        }
    }

    fn map(&mut self, map: &MapSnapshot) -> Result<(), Error> {
        match &mut self.estimates {
            Some(w) => Ok(w.map(map)?),
            None => Ok(()),
        }
    }
}

fn output_error(file: &'static str, path: &Path, source: std::io::Error) -> Error {
    Error::Output {
        file,
        path: path.to_path_buf(),
        source,
    }
}
