//! Trajectories in the TUM RGB-D benchmark's format, the one evo and most SLAM tools read: a
//! pose a line, `t x y z qx qy qz qw`, separated by spaces, `t` in seconds, the orientation a
//! unit quaternion (Hamilton, scalar last), lines starting with `#` comments.
//!
//! The vehicle's pose `(x, y, theta)` is planar: `z = 0` and the quaternion is the rotation
//! by `theta` about z, `(0, 0, sin(theta/2), cos(theta/2))`. The time is the frame's `t_us`
//! printed exactly as seconds with six decimals (integer arithmetic, no rounding), so that a
//! tool associating two files by time pairs the same frames the project's ATE pairs. Numbers
//! are printed with Rust's `Display` for `f64`, which reads back to the same value.
//!
//! Written by hand: the format is one `writeln!` a pose, and no maintained Rust crate writes it.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::Error;

/// The comment line at the top of every file the project writes.
pub const TUM_HEADER: &str = "# timestamp tx ty tz qx qy qz qw";

/// One pose as a TUM line, without its newline.
#[must_use]
pub fn tum_line(t_us: u64, pose: [f64; 3]) -> String {
    let [x, y, theta] = pose;
    let half = 0.5 * theta;
    let (qz, qw) = (half.sin(), half.cos());
    format!(
        "{}.{:06} {x} {y} 0 0 0 {qz} {qw}",
        t_us / 1_000_000,
        t_us % 1_000_000
    )
}

/// A TUM file written pose by pose (see the module docs).
#[derive(Debug)]
pub struct TumWriter {
    /// What the file is called in error messages (`--trajectory-tum`'s `TRAJ.tum`, ...).
    file: &'static str,
    path: PathBuf,
    w: BufWriter<File>,
}

impl TumWriter {
    /// Creates (or truncates) the file at `path` and writes the header comment; `file` names
    /// it in error messages.
    ///
    /// Errors: the file cannot be created or written ([`Error::Output`]).
    pub fn create(file: &'static str, path: &Path) -> Result<Self, Error> {
        let io = |source| Error::Output {
            file,
            path: path.to_path_buf(),
            source,
        };
        let mut w = BufWriter::new(File::create(path).map_err(io)?);
        writeln!(w, "{TUM_HEADER}").map_err(io)?;
        Ok(Self {
            file,
            path: path.to_path_buf(),
            w,
        })
    }

    /// A pose at `t_us`. A pose that is not finite is skipped (a TUM reader has no way to
    /// say "no pose"); the caller decides which frames have one.
    ///
    /// Errors: the file cannot be written ([`Error::Output`]).
    pub fn pose(&mut self, t_us: u64, pose: [f64; 3]) -> Result<(), Error> {
        if pose.iter().any(|v| !v.is_finite()) {
            return Ok(());
        }
        writeln!(self.w, "{}", tum_line(t_us, pose)).map_err(|source| self.error(source))
    }

    /// Flushes the file.
    ///
    /// Errors: the file cannot be written ([`Error::Output`]).
    pub fn finish(mut self) -> Result<(), Error> {
        self.w.flush().map_err(|source| self.error(source))
    }

    fn error(&self, source: std::io::Error) -> Error {
        Error::Output {
            file: self.file,
            path: self.path.clone(),
            source,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Parses a line back: `(t, x, y, z, qx, qy, qz, qw)`.
    fn parse(line: &str) -> Vec<f64> {
        line.split(' ').map(|v| v.parse().unwrap()).collect()
    }

    #[test]
    fn a_line_is_time_position_and_the_yaw_quaternion() {
        let theta = 2.0_f64;
        let v = parse(&tum_line(12_345_678, [1.5, -0.25, theta]));
        assert_eq!(v.len(), 8);
        assert_eq!(v[0], 12.345_678);
        assert_eq!(&v[1..7], &[1.5, -0.25, 0.0, 0.0, 0.0, (theta / 2.0).sin()]);
        assert_eq!(v[7], (theta / 2.0).cos());
        // A unit quaternion whose yaw is theta.
        let (qz, qw) = (v[6], v[7]);
        assert!((qz.hypot(qw) - 1.0).abs() < 1e-15);
        assert!((2.0 * qz.atan2(qw) - theta).abs() < 1e-15);
    }

    #[test]
    fn the_time_is_exact_to_the_microsecond() {
        assert!(tum_line(0, [0.0; 3]).starts_with("0.000000 "));
        assert!(tum_line(7, [0.0; 3]).starts_with("0.000007 "));
        assert!(tum_line(1_000_000, [0.0; 3]).starts_with("1.000000 "));
        // Past 2^53 microseconds a float would round; the integer split does not.
        let t = u64::MAX;
        assert!(tum_line(t, [0.0; 3]).starts_with(&format!(
            "{}.{:06} ",
            t / 1_000_000,
            t % 1_000_000
        )));
    }

    #[test]
    fn positions_read_back_exactly() {
        let pose = [0.1 + 0.2, -1e-17, std::f64::consts::PI];
        let v = parse(&tum_line(1, pose));
        assert_eq!(v[1], pose[0]);
        assert_eq!(v[2], pose[1]);
    }

    #[test]
    fn a_file_has_the_header_and_skips_poses_that_are_not_finite() {
        let dir = std::env::temp_dir().join(format!("stereonav-tum-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.tum");
        let mut w = TumWriter::create("TRAJ.tum", &path).unwrap();
        w.pose(1, [1.0, 2.0, 0.0]).unwrap();
        w.pose(2, [f64::NAN, 2.0, 0.0]).unwrap();
        w.pose(3, [3.0, 4.0, 0.5]).unwrap();
        w.finish().unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], TUM_HEADER);
        assert_eq!(lines.len(), 3);
        assert_eq!(lines[1], tum_line(1, [1.0, 2.0, 0.0]));
        assert_eq!(lines[2], tum_line(3, [3.0, 4.0, 0.5]));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn an_unwritable_path_is_an_error_naming_the_file() {
        let e = TumWriter::create("TRAJ.tum", Path::new("/nonexistent-dir/x.tum")).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("TRAJ.tum") && msg.contains("/nonexistent-dir/x.tum"),
            "{msg}"
        );
    }
}
