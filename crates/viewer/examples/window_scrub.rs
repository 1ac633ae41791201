//! Frame times of the viewer in a real window while the timeline is scrubbed.
//!
//! The headless bench (`cargo bench -p viewer --bench scrub`) times the viewer's own work and
//! egui's tessellation; this times whole frames in the window as a user sees them: egui's pass,
//! tessellation, painting by OpenGL (llvmpipe under Xvfb on a machine without a GPU) and the
//! buffer swap. The window draws the viewer of the warehouse log (simulated, replayed with
//! `pairs.stride = 10`, like the bench) or of a log given on the command line, moves the time
//! to a new position every frame as a slider dragged back and forth does, and after the frames
//! asked for prints the wall time between consecutive frames (the frame interval) and eframe's
//! own count of each frame's CPU time, then closes. vsync is off, so that the interval is the
//! frame's work, not a wait for the display.
//!
//! ```sh
//! xvfb-run -s "-screen 0 1920x1080x24" \
//!     cargo run --release -p viewer --example window_scrub -- [LOG.mcap|EST.mcap] [--frames N] [--size WxH] [--empty]
//! ```
#![allow(clippy::print_stdout, clippy::print_stderr)]

#[path = "../benches/common/mod.rs"]
mod common;

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use viewer::{Model, Viewer};

/// Frames drawn before the timing starts (fonts, the first layouts, the plot memory).
const WARM_UP: usize = 20;

/// What the command line asks for.
struct Args {
    log: Option<PathBuf>,
    frames: usize,
    size: [f32; 2],
    /// Draw one label instead of the viewer: the window's own cost (painting and swapping an
    /// almost empty frame), the floor under the viewer's frames.
    empty: bool,
}

fn parse_args() -> Result<Args, String> {
    let mut args = Args {
        log: None,
        frames: 400,
        size: [1400.0, 900.0],
        empty: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        match a.as_str() {
            "--frames" => {
                let v = it.next().ok_or("--frames needs a number")?;
                args.frames = v
                    .parse()
                    .map_err(|_| format!("--frames: not a count: {v}"))?;
            }
            "--size" => {
                let v = it.next().ok_or("--size needs WxH")?;
                let (w, h) = v
                    .split_once('x')
                    .ok_or_else(|| format!("--size: not WxH: {v}"))?;
                let parse = |s: &str| {
                    s.parse::<f32>()
                        .map_err(|_| format!("--size: not WxH: {v}"))
                };
                args.size = [parse(w)?, parse(h)?];
            }
            "--empty" => args.empty = true,
            _ if a.starts_with("--") => return Err(format!("unknown option {a}")),
            _ => args.log = Some(PathBuf::from(a)),
        }
    }
    Ok(args)
}

fn load(args: &Args) -> Result<Model, String> {
    let (path, temporary) = match &args.log {
        Some(p) => (p.clone(), false),
        None => (common::simulate_warehouse("window-scrub")?, true),
    };
    let model = common::load(&path);
    if temporary {
        std::fs::remove_file(&path).ok();
    }
    model
}

/// Per frame: the wall time since the previous frame and eframe's CPU time of the previous
/// frame, milliseconds.
#[derive(Default)]
struct Timings {
    interval_ms: Vec<f64>,
    cpu_ms: Vec<f64>,
    /// The viewer's own egui pass (`Viewer::ui`), milliseconds.
    ui_ms: Vec<f64>,
    /// `(interval, the log time the frame showed)`, to find where slow frames are.
    shown: Vec<(f64, f64)>,
}

struct App {
    viewer: Viewer,
    times: Vec<f64>,
    frame: usize,
    last: Option<Instant>,
    /// The log time of the frame being drawn, seconds.
    showing: f64,
    timings: Arc<Mutex<Timings>>,
    empty: bool,
}

impl eframe::App for App {
    fn clear_color(&self, visuals: &egui::Visuals) -> [f32; 4] {
        viewer::background(visuals).to_normalized_gamma_f32()
    }

    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        let now = Instant::now();
        if self.frame > WARM_UP
            && let (Some(last), Ok(mut t)) = (self.last, self.timings.lock())
        {
            let interval = now.duration_since(last).as_secs_f64() * 1e3;
            t.interval_ms.push(interval);
            t.shown.push((interval, self.showing));
            if let Some(cpu) = frame.info().cpu_usage {
                t.cpu_ms.push(f64::from(cpu) * 1e3);
            }
        }
        self.last = Some(now);
        if self.frame >= WARM_UP {
            match self.times.get(self.frame - WARM_UP) {
                Some(t) => self.viewer.set_time(*t),
                None => ui.send_viewport_cmd(egui::ViewportCommand::Close),
            }
        }
        self.frame += 1;
        self.showing = self.viewer.time_s();
        if self.empty {
            ui.label(format!("frame {}", self.frame));
        } else {
            let started = Instant::now();
            self.viewer.ui(ui);
            if self.frame > WARM_UP
                && let Ok(mut t) = self.timings.lock()
            {
                t.ui_ms.push(started.elapsed().as_secs_f64() * 1e3);
            }
        }
        ui.ctx().request_repaint();
    }
}

fn main() -> ExitCode {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("window_scrub: {e}");
            return ExitCode::from(2);
        }
    };
    if let Err(e) = viewer::check_display() {
        eprintln!("window_scrub: {e}");
        return ExitCode::FAILURE;
    }
    let started = Instant::now();
    let model = match load(&args) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("window_scrub: {e}");
            return ExitCode::FAILURE;
        }
    };
    println!(
        "{}: {} frames, {:.1} s, {} landmarks; loaded in {:.2} s",
        model.path.display(),
        model.replay.frames.len(),
        model.duration_s(),
        model.replay.landmarks.len(),
        started.elapsed().as_secs_f64()
    );
    let times = common::scrub_times(model.duration_s(), args.frames);
    let timings = Arc::new(Mutex::new(Timings::default()));
    let app = App {
        viewer: Viewer::new(model),
        times,
        frame: 0,
        last: None,
        showing: 0.0,
        timings: Arc::clone(&timings),
        empty: args.empty,
    };
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_inner_size(args.size)
            .with_title("stereonav view: window_scrub"),
        renderer: eframe::Renderer::Glow,
        dithering: std::env::var("DITHER").is_ok(),
        glow_options: eframe::egui_glow::GlowConfiguration {
            vsync: false,
            ..Default::default()
        },
        ..Default::default()
    };
    let run = eframe::run_native(
        "stereonav-window-scrub",
        options,
        Box::new(move |cc| {
            cc.egui_ctx.set_theme(egui::Theme::Dark);
            Ok(Box::new(app))
        }),
    );
    if let Err(e) = run {
        eprintln!("window_scrub: the window failed: {e}");
        return ExitCode::FAILURE;
    }
    let Ok(t) = timings.lock() else {
        eprintln!("window_scrub: no timings");
        return ExitCode::FAILURE;
    };
    println!(
        "scrubbing in a {}x{} window, vsync off:",
        args.size[0], args.size[1]
    );
    println!(
        "{}",
        common::summary("  frame interval", t.interval_ms.clone())
    );
    println!(
        "{}",
        common::summary("  eframe cpu_usage", t.cpu_ms.clone())
    );
    println!("{}", common::summary("  Viewer::ui", t.ui_ms.clone()));
    let mut shown = t.shown.clone();
    shown.sort_by(|a, b| b.0.total_cmp(&a.0));
    let worst: Vec<String> = shown
        .iter()
        .take(5)
        .map(|(ms, at)| format!("{ms:.1} ms at {at:.1} s"))
        .collect();
    println!("  slowest frames: {}", worst.join(", "));
    ExitCode::SUCCESS
}
