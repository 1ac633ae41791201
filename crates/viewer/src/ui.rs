//! The viewer's drawing (egui): a header, the two image planes, the top-down map, the plots of
//! the camera parameters and the NIS, and a timeline to scrub and play. [`Viewer::ui`] draws
//! one frame from the [`Model`] at the current time; it is the same in the window and in a
//! headless screenshot. A localisation run on a saved map ([`Model::localization`]) is shown
//! in the same panels: its status in the header and on a strip under the timeline, the
//! trajectory coloured by status, the missing and new lamps on the map, and plots of its
//! uncertainty, lamps matched and hypotheses instead of the camera parameters.
//!
//! Each frame costs what it shows: the current frame is found by binary search, the marks of
//! the images are computed when the frame changes (and kept), as are a bag's camera images
//! (read back from the bag, a few frames cached: [`crate::images`]), the plots draw series
//! built once at start through items that thin them to the pixels ([`crate::plot_items`]), the
//! map draws the trajectories simplified on the screen and the landmarks inside the view. What
//! is painted is chosen for software OpenGL, which fills 4x4-pixel blocks once per triangle
//! touching them: no panel backgrounds, one-pixel bars for grids, unfeathered markers in one
//! mesh.

use egui::{
    Align2, Color32, FontId, Key, Pos2, Rect, Sense, Shape, Stroke, StrokeKind, Ui, Vec2, pos2,
    vec2,
};
use egui_plot::{HLine, LineStyle, Plot, VLine};
use replay::Phase;

use crate::images::{BagImages, ImageCache};
use crate::model::{FrameMarks, Localization, Model, SourceKind};
use crate::plot_items::{Dots, Grid, Series, ThinBand, ThinLine};
use crate::thin;

/// The estimated trajectory.
const TRAJECTORY: Color32 = Color32::from_rgb(80, 200, 255);
/// The simulator's truth (trajectory, lamps, true parameter values).
const TRUTH: Color32 = Color32::from_rgb(150, 150, 150);
/// Landmarks of the map.
const LANDMARK: Color32 = Color32::from_rgb(255, 140, 0);
/// Uncertainty ellipses.
const ELLIPSE: Color32 = Color32::from_rgb(110, 150, 255);
/// An observation accepted at the current frame.
const UPDATED: Color32 = Color32::from_rgb(80, 220, 100);
/// A feature near a mapped landmark that was not updated at this frame.
const MAPPED: Color32 = Color32::from_rgb(240, 200, 60);
/// A feature of no landmark (not yet confirmed, or clutter).
const UNASSOCIATED: Color32 = Color32::from_rgb(175, 175, 175);
/// The phase switch.
const SWITCH: Color32 = Color32::from_rgb(235, 80, 80);
/// The current time on the plots.
const NOW: Color32 = Color32::from_rgb(235, 235, 235);
/// Estimates on the plots.
const ESTIMATE: Color32 = Color32::from_rgb(100, 180, 255);
/// The 3-sigma band.
const BAND: Color32 = Color32::from_rgba_premultiplied(25, 50, 90, 110);
/// A localisation run's trajectory, robot and plots while lost (the localiser's best guess).
const LOST: Color32 = Color32::from_rgb(255, 80, 170);
/// A map lamp reported missing by a localisation run (a ring around it).
const MISSING: Color32 = Color32::from_rgb(255, 50, 50);
/// A lamp a localisation run found that is not in the map (a cross).
const NEW_LAMP: Color32 = Color32::from_rgb(110, 235, 80);
/// A localisation run's position fixes on its plots.
const FIX: Color32 = Color32::from_rgb(110, 235, 80);
/// Most fixes marked on a localisation run's plots (the first ones).
const MAX_FIX_MARKERS: usize = 200;
/// Height of the localisation status strip under the timeline, points.
const STATUS_STRIP_HEIGHT: f32 = 8.0;
/// Radius of the ring around a missing lamp, points.
const MISSING_RING_RADIUS: f32 = 7.0;
/// Half the width of a new lamp's cross, points.
const CROSS_HALF_WIDTH: f32 = 4.5;
/// The left and right cameras' fields of view on the map.
const FOV: [Color32; 2] = [
    Color32::from_rgb(60, 180, 105),
    Color32::from_rgb(180, 75, 180),
];

/// The plots' grid lines show from this spacing (fading in) to full strength, points (egui_plot
/// shows them from 8 points apart: a hundred lines a plot, each a long thin pair of triangles,
/// which software OpenGL fills 4x4 pixels at a time).
const GRID_SPACING: std::ops::RangeInclusive<f32> = 30.0..=300.0;

/// Half the width of a landmark's square marker on the map, points.
const MARKER_HALF_WIDTH: f64 = 2.5;

/// Uncertainty ellipses and bands are drawn at this many standard deviations.
const SIGMAS: f64 = 3.0;
/// Most points of a drawn ellipse; a small one gets about one a point of its radius.
const ELLIPSE_SEGMENTS: usize = 32;
/// Fewest points of a drawn ellipse.
const ELLIPSE_MIN_SEGMENTS: usize = 8;
/// A bag's camera images are drawn at this gray (multiplying the image): a little dimmed, so
/// that the features and rings over a white lamp stay readable.
const IMAGE_TINT: Color32 = Color32::from_gray(190);
/// Landmark labels are drawn in the images when at most this many are projected.
const MAX_LABELS: usize = 40;
/// Playback speeds offered.
const SPEEDS: [f64; 7] = [0.25, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0];
/// At most two plots a row past this many plots.
const PLOTS_PER_COLUMN: usize = 6;

/// The colour the window (or a headless frame) is cleared to before the viewer draws: the
/// theme's panel colour, which the viewer's panels leave unpainted.
pub fn background(visuals: &egui::Visuals) -> Color32 {
    visuals.panel_fill
}

/// Where an image point `(u, v)` (pixels of a `w x h` image, as the board's features give them)
/// is drawn in an image plane at `rect`. The plane is the image: pixel `(i, j)` covers
/// `[i, i + 1) x [j, j + 1)` of `w x h` scaled to `rect`, and integer coordinates are pixel
/// centres (board-icd.md), half a pixel in.
pub fn image_to_screen(rect: Rect, [w, h]: [f64; 2], u: f64, v: f64) -> Pos2 {
    pos2(
        rect.left() + ((u + 0.5) / w) as f32 * rect.width(),
        rect.top() + ((v + 0.5) / h) as f32 * rect.height(),
    )
}

/// Where the parts were drawn in the last frame, in points (= pixels in a screenshot).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Regions {
    /// The left image plane.
    pub left_image: Rect,
    /// The right image plane.
    pub right_image: Rect,
    /// The map.
    pub map: Rect,
    /// The map's colour key (inside [`Regions::map`]).
    pub map_legend: Rect,
    /// The plots, all of them.
    pub plots: Rect,
    /// The timeline.
    pub timeline: Rect,
}

/// A parameter's series, ready for the plots.
#[derive(Debug, Clone)]
struct ParamPlot {
    param: rig_model::camera::Param,
    unit: &'static str,
    /// The 3-sigma band's edges.
    lower: Series,
    upper: Series,
    value: Series,
    truth: Option<f64>,
}

/// A localisation run's series, ready for the plots: those drawn by status split into the
/// localised and the lost frames (NaN in the other's), each drawn in its status's colour.
#[derive(Debug, Clone)]
struct LocPlots {
    /// Position 1-sigma, mm: `[localised, lost]`.
    position_sigma: [Series; 2],
    /// Heading 1-sigma, degrees: `[localised, lost]`.
    heading_sigma: [Series; 2],
    /// Distance from the truth, mm: `[localised, lost]`, when the log has truth.
    error: Option<[Series; 2]>,
    /// Map lamps matched.
    matched: Series,
    /// Relocalisation hypotheses.
    hypotheses: Series,
    /// The fixes, seconds (the first [`MAX_FIX_MARKERS`]).
    fixes_s: Vec<f64>,
}

impl LocPlots {
    fn new(model: &Model, loc: &Localization) -> Self {
        let s = &loc.series;
        let split = |values: &[f64]| split_by_status(&s.t_s, values, &s.localized);
        let whole = |values: &[f64]| Series::new(s.t_s.iter().zip(values).map(|(t, v)| [*t, *v]));
        Self {
            position_sigma: split(&s.position_sigma_mm),
            heading_sigma: split(&s.heading_sigma_deg),
            error: (!s.error_mm.is_empty()).then(|| split(&s.error_mm)),
            matched: whole(&s.matched),
            hypotheses: whole(&s.hypotheses),
            fixes_s: loc
                .fixes_t_us
                .iter()
                .take(MAX_FIX_MARKERS)
                .map(|t| model.seconds(*t))
                .collect(),
        }
    }
}

/// A series at times `t_s` split by each sample's status: `[localised, lost]`, each with NaN
/// (a break) where the other status holds.
fn split_by_status(t_s: &[f64], values: &[f64], localized: &[bool]) -> [Series; 2] {
    let part = |status: bool| {
        let points = t_s.iter().zip(values).zip(localized);
        Series::new(points.map(|((t, v), l)| [*t, if *l == status { *v } else { f64::NAN }]))
    };
    [part(true), part(false)]
}

/// One of a localisation run's plots, for one frame: its title (with the value now), its lines,
/// and whether it is a count per frame (drawn as pixel columns, see [`ThinLine::columns`]).
#[derive(Debug)]
struct LocRow<'a> {
    title: String,
    lines: Vec<(&'a Series, Stroke)>,
    columns: bool,
}

impl<'a> LocRow<'a> {
    /// A series split by status (`[localised, lost]`), each in its status's colour.
    fn by_status(title: String, series: &'a [Series; 2]) -> Self {
        let [localized, lost] = series;
        Self {
            title,
            lines: vec![
                (localized, Stroke::new(1.5, TRAJECTORY)),
                (lost, Stroke::new(1.5, LOST)),
            ],
            columns: false,
        }
    }
}

/// The map's view: world metres at the centre, metres per point.
#[derive(Debug, Clone, Copy, PartialEq)]
struct MapView {
    centre: [f64; 2],
    m_per_pt: f64,
}

/// The viewer's state: the model, the current time, playback, and caches of what the current
/// frame shows.
#[derive(Debug)]
pub struct Viewer {
    model: Model,
    time_s: f64,
    playing: bool,
    speed: f64,
    /// The frame whose marks are cached, and the marks.
    marks: Option<(usize, FrameMarks)>,
    params: Vec<ParamPlot>,
    nis_frame: Series,
    nis_mean: Series,
    nis_bound: Series,
    /// A localisation run's plots.
    loc_plots: Option<LocPlots>,
    ellipse_scale: f64,
    /// `None`: fit the whole run.
    map_view: Option<MapView>,
    follow: bool,
    regions: Regions,
    /// A ROS 2 bag's images ([`Model::images`]).
    bag: Option<BagView>,
}

/// What one image plane shows of a bag's images.
#[derive(Debug, Clone, PartialEq, Eq)]
enum PlaneImage {
    /// Nothing (before the first frame).
    Nothing,
    /// The texture, the frame's image.
    Drawn,
    /// The image could not be read: why.
    Unreadable(String),
}

/// The image planes' view of a bag's images: the decoded frames cached, the frame whose images
/// are in the two textures, and what each plane shows.
struct BagView {
    cache: ImageCache,
    /// The frame time whose images were last loaded (`Some(None)`: before the first frame).
    loaded: Option<Option<u64>>,
    textures: [Option<egui::TextureHandle>; 2],
    planes: [PlaneImage; 2],
}

impl std::fmt::Debug for BagView {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BagView")
            .field("cache", &self.cache)
            .field("loaded", &self.loaded)
            .field(
                "textures",
                &self.textures.each_ref().map(|t| t.as_ref().map(|t| t.id())),
            )
            .field("planes", &self.planes)
            .finish()
    }
}

impl BagView {
    fn new() -> Self {
        Self {
            cache: ImageCache::new(),
            loaded: None,
            textures: [None, None],
            planes: [PlaneImage::Nothing, PlaneImage::Nothing],
        }
    }

    /// Loads the images of the frame at `t_us` into the textures, unless they are there: from
    /// the cache, or read from the bag. One texture a side, updated in place.
    fn load(&mut self, ctx: &egui::Context, images: &BagImages, t_us: Option<u64>) {
        if self.loaded == Some(t_us) {
            return;
        }
        self.loaded = Some(t_us);
        let Some(t_us) = t_us else {
            self.planes = [PlaneImage::Nothing, PlaneImage::Nothing];
            return;
        };
        let frame = self.cache.frame(images, t_us);
        let max_side = ctx.input(|i| i.max_texture_side);
        for (k, side) in [Side::Left, Side::Right].into_iter().enumerate() {
            let pixels = match &frame {
                Ok(g) => match side {
                    Side::Left => g.left.as_ref(),
                    Side::Right => g.right.as_ref(),
                },
                Err(why) => Err(why),
            };
            let (Some(plane), Some(texture)) = (self.planes.get_mut(k), self.textures.get_mut(k))
            else {
                continue;
            };
            *plane = match pixels {
                Ok(pixels) => {
                    let image = gray_image(pixels, images.size(), max_side);
                    match texture {
                        Some(t) => t.set(image, egui::TextureOptions::LINEAR),
                        None => {
                            *texture = Some(ctx.load_texture(
                                format!("stereonav {} image", side.name()),
                                image,
                                egui::TextureOptions::LINEAR,
                            ));
                        }
                    }
                    PlaneImage::Drawn
                }
                Err(why) => PlaneImage::Unreadable(why.clone()),
            };
        }
    }
}

/// An egui image of gray `pixels` of `size`, shrunk by a whole factor (the mean of each
/// block) when a side is longer than `max_side`, the largest texture the painter takes.
fn gray_image(pixels: &[u8], size: [u32; 2], max_side: usize) -> egui::ColorImage {
    let [w, h] = size.map(|s| s as usize);
    let k = w.max(h).div_ceil(max_side.max(1)).max(1);
    if k == 1 && pixels.len() == w * h {
        return egui::ColorImage::from_gray([w, h], pixels);
    }
    let (tw, th) = (w / k, h / k);
    let at = |x: usize, y: usize| u32::from(pixels.get(y * w + x).copied().unwrap_or(0));
    let block = |tx: usize, ty: usize| {
        let sum: u32 = (0..k)
            .flat_map(|dy| (0..k).map(move |dx| (dx, dy)))
            .map(|(dx, dy)| at(tx * k + dx, ty * k + dy))
            .sum();
        // A mean of 8-bit values: at most 255.
        u8::try_from(sum / (k * k) as u32).unwrap_or(u8::MAX)
    };
    egui::ColorImage::from_gray_iter(
        [tw, th],
        (0..th)
            .flat_map(|ty| (0..tw).map(move |tx| (tx, ty)))
            .map(|(tx, ty)| block(tx, ty)),
    )
}

/// A path on the screen thinned to what its pixels show ([`thin::simplify`]).
fn thin_path(path: &[Pos2]) -> Vec<Pos2> {
    let px: Vec<[f32; 2]> = path.iter().map(|p| [p.x, p.y]).collect();
    thin::simplify(&px, thin::TOLERANCE_PX, &[])
        .iter()
        .filter_map(|k| path.get(*k).copied())
        .collect()
}

impl Default for Regions {
    fn default() -> Self {
        Self {
            left_image: Rect::NOTHING,
            right_image: Rect::NOTHING,
            map: Rect::NOTHING,
            map_legend: Rect::NOTHING,
            plots: Rect::NOTHING,
            timeline: Rect::NOTHING,
        }
    }
}

impl Viewer {
    /// A viewer of `model` at its end.
    pub fn new(model: Model) -> Self {
        let params = model
            .params
            .iter()
            .map(|s| {
                let band = |k: f64| {
                    Series::new(
                        s.t_s
                            .iter()
                            .zip(s.value.iter().zip(&s.sigma))
                            .map(|(t, (v, sd))| [*t, v + k * SIGMAS * sd]),
                    )
                };
                ParamPlot {
                    param: s.param,
                    unit: s.unit,
                    lower: band(-1.0),
                    upper: band(1.0),
                    value: band(0.0),
                    truth: s.truth,
                }
            })
            .collect();
        let ellipse_scale = auto_ellipse_scale(&model);
        let model_images = model.images.is_some();
        let loc_plots = model
            .localization
            .as_ref()
            .map(|loc| LocPlots::new(&model, loc));
        Self {
            loc_plots,
            time_s: model.duration_s(),
            params,
            nis_frame: Series::new(model.nis.frame_mean.iter().copied()),
            nis_mean: Series::new(model.nis.window_mean.iter().copied()),
            nis_bound: Series::new(model.nis.window_bound.iter().copied()),
            ellipse_scale,
            model,
            playing: false,
            speed: 1.0,
            marks: None,
            map_view: None,
            follow: false,
            regions: Regions::default(),
            bag: model_images.then(BagView::new),
        }
    }

    /// The model shown.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The current time, seconds from the log's start.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Moves to `t_s` seconds from the log's start (clamped to the log).
    pub fn set_time(&mut self, t_s: f64) {
        self.time_s = t_s.clamp(0.0, self.model.duration_s().max(0.0));
    }

    /// Where the parts were drawn in the last frame.
    pub fn regions(&self) -> Regions {
        self.regions
    }

    /// The decoded images of a bag's last frames shown ([`Model::images`]): what the viewer
    /// holds of the bag's pixels, besides the two textures of the frame shown.
    pub fn image_cache(&self) -> Option<&ImageCache> {
        self.bag.as_ref().map(|b| &b.cache)
    }

    /// Draws one frame of the viewer into `ui` (the whole window), and handles its input.
    ///
    /// The panels paint no background of their own: the window is cleared to
    /// [`background`] (as the headless renderer clears its frame), which saves a layer of
    /// blended pixels over the whole window each frame (software OpenGL spends most of a
    /// frame filling pixels).
    pub fn ui(&mut self, ui: &mut Ui) {
        self.input(ui);
        let style = ui.style().clone();
        let bar = egui::Frame::side_top_panel(&style).fill(Color32::TRANSPARENT);
        egui::Panel::top("stereonav-header")
            .frame(bar)
            .show(ui, |ui| self.header(ui));
        let timeline = egui::Panel::bottom("stereonav-timeline")
            .frame(bar)
            .show(ui, |ui| self.timeline(ui));
        self.regions.timeline = timeline.response.rect;
        let width = ui.available_width();
        let plots = egui::Panel::right("stereonav-plots")
            .frame(bar)
            .resizable(true)
            .default_size((width * 0.42).max(300.0))
            .show(ui, |ui| self.plots(ui));
        self.regions.plots = plots.response.rect;
        egui::CentralPanel::default()
            .frame(egui::Frame::central_panel(&style).fill(Color32::TRANSPARENT))
            .show(ui, |ui| {
                self.images(ui);
                self.map(ui);
            });
    }

    /// Keys and playback.
    fn input(&mut self, ui: &Ui) {
        let (space, left, right, home, end, dt) = ui.input(|i| {
            (
                i.key_pressed(Key::Space),
                i.key_pressed(Key::ArrowLeft),
                i.key_pressed(Key::ArrowRight),
                i.key_pressed(Key::Home),
                i.key_pressed(Key::End),
                i.stable_dt,
            )
        });
        let typing = ui.ctx().text_edit_focused();
        if !typing {
            if space {
                self.toggle_play();
            }
            if left {
                self.step(-1);
            }
            if right {
                self.step(1);
            }
            if home {
                self.set_time(0.0);
            }
            if end {
                self.set_time(self.model.duration_s());
            }
        }
        if self.playing {
            let end = self.model.duration_s();
            self.time_s += f64::from(dt.min(0.1)) * self.speed;
            if self.time_s >= end {
                self.time_s = end;
                self.playing = false;
            }
            ui.ctx().request_repaint();
        }
    }

    fn toggle_play(&mut self) {
        if !self.playing && self.time_s >= self.model.duration_s() {
            self.time_s = 0.0;
        }
        self.playing = !self.playing;
    }

    /// One frame back or forward.
    fn step(&mut self, by: isize) {
        let frames = &self.model.replay.frames;
        let next = match self.model.frame_at(self.time_s) {
            Some(i) => i.saturating_add_signed(by),
            None if by > 0 => 0,
            None => return,
        };
        if let Some(f) = frames.get(next.min(frames.len().saturating_sub(1))) {
            self.time_s = self.model.seconds(f.t_us);
        }
    }

    fn header(&self, ui: &mut Ui) {
        let m = &self.model;
        let name = file_name(&m.path);
        if let Some(loc) = &m.localization {
            self.localization_header(ui, &name, loc);
            return;
        }
        let bag = m.images.is_some();
        let source = match (m.kind, m.replay.phase1_skipped, bag) {
            (SourceKind::VehicleLog, true, false) => "vehicle log, replayed with phase 1 skipped",
            (SourceKind::VehicleLog, false, false) => "vehicle log, replayed",
            (SourceKind::VehicleLog, true, true) => "ROS 2 bag, replayed with phase 1 skipped",
            (SourceKind::VehicleLog, false, true) => "ROS 2 bag, replayed",
            (SourceKind::Estimates, _, _) => "estimates file",
        };
        let frame = m.frame_at(self.time_s);
        let phase = match m.phase_at(self.time_s) {
            Some(Phase::Calibrating) => "phase 1 (self-calibration)",
            Some(Phase::Navigating) => "phase 2 (EKF SLAM)",
            None => "no frames",
        };
        let landmarks = frame.and_then(|i| m.frame(i)).map_or(0, |f| f.landmarks);
        ui.horizontal(|ui| {
            ui.strong(name);
            ui.label(format!("({source})"));
            ui.separator();
            ui.label(format!(
                "frame {} of {}",
                frame.map_or(0, |i| i + 1),
                m.replay.frames.len()
            ));
            ui.separator();
            ui.label(phase);
            ui.separator();
            ui.label(format!("{landmarks} landmarks"));
            if let Some(t) = m.replay.phase_switch_t_us {
                ui.separator();
                ui.colored_label(SWITCH, format!("phase switch at {:.1} s", m.seconds(t)));
            }
            if !m.warnings.is_empty() {
                ui.separator();
                ui.colored_label(MAPPED, format!("{} warning(s)", m.warnings.len()))
                    .on_hover_text(m.warnings.join("\n"));
            }
        });
    }

    /// The header of a localisation run: the status at the current frame (localised, with the
    /// lamps matched; or lost, with the hypotheses), the map's lamps missing and new, the fixes.
    fn localization_header(&self, ui: &mut Ui, name: &str, loc: &Localization) {
        let m = &self.model;
        let frame = m.frame_at(self.time_s);
        ui.horizontal(|ui| {
            ui.strong(name);
            ui.label(format!(
                "(vehicle log, localised on the map {})",
                file_name(&loc.map_path)
            ));
            ui.separator();
            ui.label(format!(
                "frame {} of {}",
                frame.map_or(0, |i| i + 1),
                m.replay.frames.len()
            ));
            ui.separator();
            let (text, colour) = localization_status(frame.and_then(|i| loc.frame(i)));
            ui.colored_label(colour, text);
            ui.separator();
            ui.label(format!("{} map lamps,", loc.seen.len()));
            ui.colored_label(MISSING, format!("{} missing,", loc.missing.len()));
            ui.colored_label(NEW_LAMP, format!("{} new", loc.new_lamps.len()));
            ui.separator();
            let fixes: Vec<String> = loc
                .fixes_t_us
                .iter()
                .take(3)
                .map(|t| format!("{:.2} s", m.seconds(*t)))
                .collect();
            let more = loc.fixes_t_us.len().saturating_sub(fixes.len());
            ui.label(match (fixes.is_empty(), more) {
                (true, _) => "never localised".to_string(),
                (false, 0) => format!("fixed at {}", fixes.join(", ")),
                (false, n) => format!("fixed at {} and {n} more", fixes.join(", ")),
            })
            .on_hover_text(format!(
                "{} of {} frames localised; lost {} times after a gap, {} without odometry, {} when the lamps stopped fitting, {} too uncertain",
                loc.localized_frames,
                loc.frames.len(),
                loc.lost_by_reason[0],
                loc.lost_by_reason[1],
                loc.lost_by_reason[2],
                loc.lost_by_reason[3],
            ));
            if !m.warnings.is_empty() {
                ui.separator();
                ui.colored_label(MAPPED, format!("{} warning(s)", m.warnings.len()))
                    .on_hover_text(m.warnings.join("\n"));
            }
        });
    }

    fn timeline(&mut self, ui: &mut Ui) {
        let end = self.model.duration_s().max(0.0);
        let slider = ui.horizontal(|ui| {
            let label = if self.playing { "pause" } else { "play" };
            if ui.button(label).clicked() {
                self.toggle_play();
            }
            if ui
                .button("<")
                .on_hover_text("previous frame (left arrow)")
                .clicked()
            {
                self.step(-1);
            }
            if ui
                .button(">")
                .on_hover_text("next frame (right arrow)")
                .clicked()
            {
                self.step(1);
            }
            egui::ComboBox::from_id_salt("stereonav-speed")
                .width(60.0)
                .selected_text(format!("{}x", self.speed))
                .show_ui(ui, |ui| {
                    for s in SPEEDS {
                        ui.selectable_value(&mut self.speed, s, format!("{s}x"));
                    }
                });
            ui.label(format!("{:8.3} s / {end:.3} s", self.time_s));
            ui.spacing_mut().slider_width = (ui.available_width() - 16.0).max(50.0);
            let slider = ui.add(
                egui::Slider::new(&mut self.time_s, 0.0..=end)
                    .show_value(false)
                    .smart_aim(false),
            );
            if slider.dragged() {
                self.playing = false;
            }
            // The phase switch on the timeline.
            if let Some(t) = self.model.replay.phase_switch_t_us
                && end > 0.0
            {
                let r = slider.rect;
                let inset = r.height() / 2.0;
                let x = r.left()
                    + inset
                    + (r.width() - 2.0 * inset) * (self.model.seconds(t) / end) as f32;
                ui.painter().line_segment(
                    [pos2(x, r.top()), pos2(x, r.bottom())],
                    Stroke::new(2.0, SWITCH),
                );
            }
            slider.rect
        });
        if let Some(loc) = &self.model.localization {
            self.status_strip(ui, loc, slider.inner, end);
        }
    }

    /// A localisation run's status over time under the timeline's slider (`slider`: its
    /// rectangle), localised and lost in their colours, with the status at the current frame.
    fn status_strip(&self, ui: &mut Ui, loc: &Localization, slider: Rect, end: f64) {
        let m = &self.model;
        ui.horizontal(|ui| {
            let (text, colour) =
                localization_status(m.frame_at(self.time_s).and_then(|i| loc.frame(i)));
            ui.colored_label(colour, text);
            let (row, _) = ui.allocate_exact_size(
                vec2(ui.available_width(), STATUS_STRIP_HEIGHT),
                Sense::hover(),
            );
            // Aligned with the slider's rail (inset by half its height at each end).
            let inset = slider.height() / 2.0;
            let (x0, x1) = (slider.left() + inset, slider.right() - inset);
            if !(end > 0.0 && x1 > x0) {
                return;
            }
            let x_at = |t_s: f64| x0 + (x1 - x0) * (t_s / end).clamp(0.0, 1.0) as f32;
            let mut strip = egui::Mesh::default();
            for (k, run) in loc.status.iter().enumerate() {
                let start = loc
                    .frame(run.frames.start)
                    .map_or(0.0, |f| m.seconds(f.t_us));
                // Up to the next stretch's first frame, the last to the end.
                let stop = loc
                    .status
                    .get(k + 1)
                    .and_then(|next| loc.frame(next.frames.start))
                    .map_or(end, |f| m.seconds(f.t_us));
                let (a, b) = (x_at(start).floor(), x_at(stop).floor());
                let colour = if run.localized { TRAJECTORY } else { LOST };
                strip.add_colored_rect(
                    Rect::from_min_max(pos2(a, row.top()), pos2(b.max(a + 1.0), row.bottom())),
                    colour,
                );
            }
            ui.painter().add(strip);
            let now = x_at(self.time_s).floor();
            ui.painter().rect_filled(
                Rect::from_min_max(
                    pos2(now - 1.0, row.top() - 2.0),
                    pos2(now + 1.0, row.bottom() + 2.0),
                ),
                0.0,
                NOW,
            );
        });
    }

    /// The two image planes side by side.
    fn images(&mut self, ui: &mut Ui) {
        let frame = self.model.frame_at(self.time_s);
        if let Some(i) = frame
            && self.marks.as_ref().is_none_or(|(cached, _)| *cached != i)
        {
            self.marks = Some((i, self.model.marks(i)));
        }
        let marks = match (frame, &self.marks) {
            (Some(i), Some((cached, m))) if *cached == i => Some(m),
            _ => None,
        };
        // A bag's images of the frame: read when the frame changes.
        if let (Some(bag), Some(images)) = (&mut self.bag, &self.model.images) {
            let t_us = frame.and_then(|i| self.model.frame(i)).map(|f| f.t_us);
            bag.load(ui.ctx(), images, t_us);
        }
        let [w, h] = self.model.image_size;
        let aspect = (h / w.max(1.0)) as f32;
        let gap = 8.0;
        let width = ((ui.available_width() - gap) / 2.0).max(50.0);
        let height = (width * aspect).min(ui.available_height() * 0.45);
        let width = height / aspect;
        let no_features = self.model.features.frames.is_empty();
        let current = frame.and_then(|i| self.model.frame(i));
        // What the source says of the frame's observations: the navigator's associations (a
        // replay), or, in an estimates file without features, the landmarks updated. Never a
        // count the viewer made up: a localisation run's count of map lamps matched is in the
        // header (the localiser does not say which features).
        let observations = match (marks.and_then(|m| m.on_landmarks), &self.model.localization) {
            (_, Some(_)) => None,
            (Some(on), None) => Some(format!("{on} on landmarks")),
            (None, None) if no_features => {
                current.map(|f| format!("{} landmarks updated", f.observed.len()))
            }
            (None, None) => None,
        };
        let landmarks = if self.model.localization.is_some() {
            "map lamps"
        } else {
            "landmarks"
        };
        ui.horizontal(|ui| {
            for side in [Side::Left, Side::Right] {
                ui.vertical(|ui| {
                    let (features, projected) = match (marks, side) {
                        (Some(m), Side::Left) => (&m.left[..], &m.projected_left[..]),
                        (Some(m), Side::Right) => (&m.right[..], &m.projected_right[..]),
                        (None, _) => (&[][..], &[][..]),
                    };
                    let mut label = format!("{} image: ", side.name());
                    if !no_features {
                        label.push_str(&format!("{} features, ", features.len()));
                    }
                    if let Some(o) = &observations {
                        label.push_str(&format!("{o}, "));
                    }
                    label.push_str(&format!("{} {landmarks} in view", projected.len()));
                    ui.label(label);
                    let (rect, _) = ui.allocate_exact_size(vec2(width, height), Sense::hover());
                    match side {
                        Side::Left => self.regions.left_image = rect,
                        Side::Right => self.regions.right_image = rect,
                    }
                    let painter = ui.painter_at(rect);
                    // A bag's image of the frame: the raw image the host's detector saw, in
                    // the features' own pixels (the rings too are taken through the lens
                    // into them), so it is drawn as it is, no remapping.
                    let plane = self.bag.as_ref().and_then(|b| {
                        let k = usize::from(side == Side::Right);
                        Some((b.planes.get(k)?, b.textures.get(k)?.as_ref()))
                    });
                    match plane {
                        Some((PlaneImage::Drawn, Some(texture))) => {
                            painter.image(
                                texture.id(),
                                rect,
                                Rect::from_min_max(pos2(0.0, 0.0), pos2(1.0, 1.0)),
                                IMAGE_TINT,
                            );
                        }
                        Some((PlaneImage::Unreadable(why), _)) => {
                            let galley = painter.layout(
                                format!("no image: {why}"),
                                FontId::proportional(12.0),
                                Color32::from_gray(160),
                                rect.width() - 16.0,
                            );
                            painter.galley(rect.min + vec2(8.0, 8.0), galley, Color32::WHITE);
                        }
                        _ => {}
                    }
                    // Outlined, not filled: the board's stream carries no images (see
                    // [`Viewer::ui`]).
                    painter.rect_stroke(
                        rect,
                        0.0,
                        Stroke::new(1.0, Color32::from_gray(90)),
                        StrokeKind::Inside,
                    );
                    let to_screen = |u: f64, v: f64| image_to_screen(rect, [w, h], u, v);
                    let labels = projected.len() <= MAX_LABELS;
                    for p in projected {
                        let colour = if p.observed { UPDATED } else { MAPPED };
                        let at = to_screen(p.u, p.v);
                        painter.circle_stroke(at, 6.0, Stroke::new(1.0, colour));
                        if labels {
                            painter.text(
                                at + vec2(7.0, -7.0),
                                Align2::LEFT_BOTTOM,
                                p.id.to_string(),
                                FontId::monospace(10.0),
                                colour,
                            );
                        }
                    }
                    for f in features {
                        let colour = match (f.landmark, f.observed) {
                            (Some(_), true) => UPDATED,
                            (Some(_), false) => MAPPED,
                            (None, _) => UNASSOCIATED,
                        };
                        painter.circle_filled(
                            to_screen(f64::from(f.u), f64::from(f.v)),
                            2.5,
                            colour,
                        );
                    }
                    if no_features {
                        painter.text(
                            rect.center_bottom() - vec2(0.0, 6.0),
                            Align2::CENTER_BOTTOM,
                            "no board features in an estimates file: landmarks projected",
                            FontId::proportional(12.0),
                            Color32::from_gray(140),
                        );
                    }
                });
                ui.add_space(gap);
            }
        });
        ui.horizontal(|ui| {
            let key = |ui: &mut Ui, colour: Color32, text: &str| {
                let (r, _) = ui.allocate_exact_size(vec2(10.0, 10.0), Sense::hover());
                ui.painter().circle_filled(r.center(), 3.5, colour);
                ui.label(text);
            };
            // Where the rings are: projected in the rectified model, or taken on through the
            // rig's lenses into the board's raw pixels.
            let rings = if self.model.lens.is_some() {
                "through the lens"
            } else {
                "projected"
            };
            if self.model.localization.is_some() {
                // The localiser reports how many lamps it matched, not which.
                key(ui, MAPPED, "near a map lamp");
                key(ui, UNASSOCIATED, "no map lamp");
                ui.label(format!("(rings: the map's lamps at the pose, {rings})"));
            } else {
                key(ui, UPDATED, "observation accepted");
                key(ui, MAPPED, "rejected by the gate");
                key(ui, UNASSOCIATED, "no landmark");
                ui.label(format!("(rings: landmarks {rings}, green if updated)"));
            }
        });
    }

    /// The top-down map.
    fn map(&mut self, ui: &mut Ui) {
        let m = &self.model;
        let frame = m.frame_at(self.time_s);
        ui.horizontal(|ui| {
            ui.label("map (top view, world frame, metres)");
            ui.separator();
            ui.label(format!("{SIGMAS:.0}-sigma ellipses x"));
            egui::ComboBox::from_id_salt("stereonav-ellipse-scale")
                .width(70.0)
                .selected_text(format!("{}", self.ellipse_scale))
                .show_ui(ui, |ui| {
                    for s in [1.0, 10.0, 100.0, 1000.0, 10000.0] {
                        ui.selectable_value(&mut self.ellipse_scale, s, format!("{s}"));
                    }
                });
            ui.checkbox(&mut self.follow, "follow the robot");
            if ui.button("fit").clicked() {
                self.map_view = None;
                self.follow = false;
            }
        });
        let size = ui.available_size().max(vec2(50.0, 50.0));
        let (response, painter) = ui.allocate_painter(size, Sense::click_and_drag());
        let rect = response.rect;
        self.regions.map = rect;
        // An outline, not a filled background: see [`Viewer::ui`].
        painter.rect_stroke(
            rect,
            0.0,
            Stroke::new(1.0, Color32::from_gray(70)),
            StrokeKind::Inside,
        );

        // The view: fit, follow, or the user's pan and zoom.
        let fit = {
            let [x0, y0, x1, y1] = m.bounds;
            let margin = 0.08 * (x1 - x0).max(y1 - y0).max(1.0);
            let m_per_pt = ((x1 - x0 + 2.0 * margin) / f64::from(rect.width()))
                .max((y1 - y0 + 2.0 * margin) / f64::from(rect.height()));
            MapView {
                centre: [(x0 + x1) / 2.0, (y0 + y1) / 2.0],
                m_per_pt,
            }
        };
        let mut view = self.map_view.unwrap_or(fit);
        if self.follow
            && let Some(f) = frame.and_then(|i| m.frame(i))
            && f.pose[..2].iter().all(|v| v.is_finite())
        {
            view.centre = [f.pose[0], f.pose[1]];
        }
        if response.dragged() {
            let d = response.drag_delta();
            view.centre[0] -= f64::from(d.x) * view.m_per_pt;
            view.centre[1] += f64::from(d.y) * view.m_per_pt;
            self.map_view = Some(view);
            self.follow = false;
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0 {
                view.m_per_pt *= f64::from((-scroll / 200.0).exp());
                self.map_view = Some(view);
            }
        }
        if response.double_clicked() {
            self.map_view = None;
            self.follow = false;
            view = fit;
        }
        let (cx, cy) = (rect.center().x, rect.center().y);
        let to_screen = move |p: [f64; 2]| -> Pos2 {
            pos2(
                cx + ((p[0] - view.centre[0]) / view.m_per_pt) as f32,
                cy - ((p[1] - view.centre[1]) / view.m_per_pt) as f32,
            )
        };
        let visible = rect.expand(20.0);

        grid(&painter, rect, view);

        // Truth: lamps and trajectory.
        if let Some(truth) = &m.truth {
            let mut lamps = egui::Mesh::default();
            for lamp in &truth.lamps {
                let at = to_screen([lamp[0], lamp[1]]);
                if visible.contains(at) {
                    plus_marker(&mut lamps, at, TRUTH);
                }
            }
            painter.add(lamps);
            let t_us = m.t_us_at(self.time_s);
            let upto = m.truth_trajectory.partition_point(|(t, _)| *t <= t_us);
            let path: Vec<Pos2> = m
                .truth_trajectory
                .iter()
                .take(upto)
                .map(|(_, p)| to_screen(*p))
                .collect();
            if path.len() >= 2 {
                painter.add(Shape::line(thin_path(&path), Stroke::new(1.5, TRUTH)));
            }
        }

        // Fields of view at the current frame.
        if let Some(i) = frame {
            for (footprint, colour) in m.field_of_view(i).iter().zip(FOV) {
                if let Some(corners) = footprint {
                    let pts: Vec<Pos2> = corners.iter().map(|c| to_screen(*c)).collect();
                    painter.add(Shape::convex_polygon(
                        pts,
                        colour.gamma_multiply(0.08),
                        Stroke::new(1.5, colour),
                    ));
                }
            }
        }

        // The estimated trajectory up to now: a localisation run's in stretches by status.
        if let (Some(i), Some(loc)) = (frame, &m.localization) {
            let current = m
                .frame(i)
                .filter(|f| f.pose[..2].iter().all(|v| v.is_finite()))
                .map(|f| to_screen([f.pose[0], f.pose[1]]));
            let drawn = loc
                .track
                .partition_point(|run| run.points.first().is_some_and(|(k, _)| *k <= i));
            for (n, run) in loc.track.iter().take(drawn).enumerate() {
                let upto = run.points.partition_point(|(k, _)| *k <= i);
                let mut path: Vec<Pos2> = run
                    .points
                    .iter()
                    .take(upto)
                    .map(|(_, p)| to_screen(*p))
                    .collect();
                // The last stretch drawn reaches the current pose (see `TrackRun`).
                if n + 1 == drawn
                    && let Some(at) = current
                {
                    path.push(at);
                }
                let colour = if run.localized { TRAJECTORY } else { LOST };
                if path.len() >= 2 {
                    painter.add(Shape::line(thin_path(&path), Stroke::new(2.0, colour)));
                }
            }
        } else if let Some(i) = frame {
            let upto = m.trajectory.partition_point(|(k, _)| *k <= i);
            let mut path: Vec<Pos2> = m
                .trajectory
                .iter()
                .take(upto)
                .map(|(_, p)| to_screen(*p))
                .collect();
            if let Some(f) = m.frame(i)
                && f.pose[..2].iter().all(|v| v.is_finite())
            {
                path.push(to_screen([f.pose[0], f.pose[1]]));
            }
            if path.len() >= 2 {
                painter.add(Shape::line(thin_path(&path), Stroke::new(2.0, TRAJECTORY)));
            }
        }

        // The map at this time, with the uncertainty ellipses.
        let t_us = m.t_us_at(self.time_s);
        let scale = self.ellipse_scale;
        let observed: &[u64] = frame
            .and_then(|i| m.frame(i))
            .map_or(&[], |f| f.observed.as_slice());
        let mut markers = egui::Mesh::default();
        for l in m.map_at(t_us) {
            let centre = [l.position[0], l.position[1]];
            if !centre.iter().all(|v| v.is_finite()) {
                continue;
            }
            let at = to_screen(centre);
            if !visible.contains(at) {
                continue;
            }
            let cov = [
                [l.covariance[0][0], l.covariance[0][1]],
                [l.covariance[1][0], l.covariance[1][1]],
            ];
            if let Some(outline) = ellipse(centre, cov, SIGMAS * scale, view.m_per_pt) {
                let pts: Vec<Pos2> = outline.iter().map(|p| to_screen(*p)).collect();
                painter.add(Shape::closed_line(pts, Stroke::new(1.0, ELLIPSE)));
            }
            let colour = if observed.contains(&l.id) {
                UPDATED
            } else {
                LANDMARK
            };
            square_marker(&mut markers, at, colour);
            if m.localization
                .as_ref()
                .is_some_and(|loc| loc.is_missing(l.id))
            {
                painter.circle_stroke(at, MISSING_RING_RADIUS, Stroke::new(1.5, MISSING));
                painter.text(
                    at + vec2(MISSING_RING_RADIUS + 2.0, -MISSING_RING_RADIUS),
                    Align2::LEFT_BOTTOM,
                    format!("{} missing", l.id),
                    FontId::proportional(10.0),
                    MISSING,
                );
            }
        }
        painter.add(markers);

        // A localisation run's new lamps, with their ellipses.
        if let Some(loc) = &m.localization {
            for l in &loc.new_lamps {
                let centre = [l.position[0], l.position[1]];
                if !centre.iter().all(|v| v.is_finite()) {
                    continue;
                }
                let at = to_screen(centre);
                if !visible.contains(at) {
                    continue;
                }
                let cov = [
                    [l.covariance[0][0], l.covariance[0][1]],
                    [l.covariance[1][0], l.covariance[1][1]],
                ];
                if let Some(outline) = ellipse(centre, cov, SIGMAS * scale, view.m_per_pt) {
                    let pts: Vec<Pos2> = outline.iter().map(|p| to_screen(*p)).collect();
                    painter.add(Shape::closed_line(pts, Stroke::new(1.0, NEW_LAMP)));
                }
                cross(&painter, at, NEW_LAMP);
                painter.text(
                    at + vec2(CROSS_HALF_WIDTH + 2.0, -CROSS_HALF_WIDTH),
                    Align2::LEFT_BOTTOM,
                    "new",
                    FontId::proportional(10.0),
                    NEW_LAMP,
                );
            }
        }

        // While lost: the hypotheses being weighed, each a hollow arrow at its pose with how
        // far behind the best it is (nats), so that one sees why no fix is declared yet.
        if let (Some(loc), Some(i)) = (&m.localization, frame)
            && let Some(f) = loc.frame(i)
            && !f.localized
        {
            for w in f.weighed.iter().flatten() {
                let at = to_screen([w.pose.x, w.pose.y]);
                let (s, c) = (w.pose.theta.sin() as f32, w.pose.theta.cos() as f32);
                let ahead = vec2(c, -s);
                let side = vec2(s, c);
                painter.add(Shape::closed_line(
                    vec![
                        at + ahead * 10.0,
                        at - ahead * 5.0 + side * 5.0,
                        at - ahead * 5.0 - side * 5.0,
                    ],
                    Stroke::new(1.5, LOST),
                ));
                let label = if w.behind_nats <= 0.0 {
                    format!("best, {} frames", w.age)
                } else {
                    format!("-{:.0} nats", w.behind_nats)
                };
                painter.text(
                    at + vec2(8.0, 8.0),
                    Align2::LEFT_TOP,
                    label,
                    FontId::proportional(10.0),
                    LOST,
                );
            }
        }

        // The robot: its pose, heading and pose ellipse (a localisation run's in the colour of
        // its status).
        let robot = match (&m.localization, frame) {
            (Some(loc), Some(i)) if !loc.frame(i).is_some_and(|f| f.localized) => LOST,
            _ => TRAJECTORY,
        };
        if let Some(f) = frame.and_then(|i| m.frame(i))
            && f.pose.iter().all(|v| v.is_finite())
        {
            let [x, y, theta] = f.pose;
            let cov = [
                [f.pose_covariance[0][0], f.pose_covariance[0][1]],
                [f.pose_covariance[1][0], f.pose_covariance[1][1]],
            ];
            if let Some(outline) = ellipse([x, y], cov, SIGMAS * scale, view.m_per_pt) {
                let pts: Vec<Pos2> = outline.iter().map(|p| to_screen(*p)).collect();
                painter.add(Shape::closed_line(pts, Stroke::new(1.0, robot)));
            }
            let at = to_screen([x, y]);
            let (s, c) = (theta.sin() as f32, theta.cos() as f32);
            let ahead = vec2(c, -s);
            let side = vec2(s, c);
            let tip = at + ahead * 12.0;
            painter.add(Shape::convex_polygon(
                vec![
                    tip,
                    at - ahead * 6.0 + side * 6.0,
                    at - ahead * 6.0 - side * 6.0,
                ],
                robot,
                Stroke::new(1.0, Color32::WHITE),
            ));
        }

        self.regions.map_legend =
            legend(&painter, rect, m.truth.is_some(), m.localization.is_some());
        response.on_hover_text_at_pointer(
            "drag to pan, scroll to zoom, double-click to fit the whole run",
        );
    }

    /// A localisation run's plots over time: the pose's uncertainty, its distance from the
    /// truth (when the log has it), the map lamps matched and the relocalisation hypotheses,
    /// with the fixes (green, dashed) and the current time.
    fn localization_plots(&mut self, ui: &mut Ui) {
        let (Some(plots), Some(loc)) = (&self.loc_plots, &self.model.localization) else {
            return;
        };
        let now = self.time_s;
        let end = self.model.duration_s();
        let current = self.model.frame_at(now).and_then(|i| loc.frame(i));
        let pose = current.filter(|f| f.pose.is_some());
        let value = |v: Option<f64>, decimals: usize| {
            v.filter(|v| v.is_finite())
                .map_or_else(|| "no pose".to_string(), |v| format!("{v:.decimals$}"))
        };
        let error_now = self.model.frame_at(now).and_then(|i| {
            let k = loc.series.frame.binary_search(&i).ok()?;
            loc.series.error_mm.get(k).copied()
        });
        let mut rows = vec![
            LocRow::by_status(
                format!(
                    "position 1-sigma [mm]: {}",
                    value(pose.map(|f| f.sigma[0].hypot(f.sigma[1]) * 1e3), 3)
                ),
                &plots.position_sigma,
            ),
            LocRow::by_status(
                format!(
                    "heading 1-sigma [deg]: {}",
                    value(pose.map(|f| f.sigma[2].to_degrees()), 4)
                ),
                &plots.heading_sigma,
            ),
        ];
        if let Some(error) = &plots.error {
            rows.push(LocRow::by_status(
                format!("distance from the truth [mm]: {}", value(error_now, 3)),
                error,
            ));
        }
        let count_now = |n: fn(&replay::LocalizedFrame) -> u32| {
            current.map_or_else(|| "-".to_string(), |f| n(f).to_string())
        };
        rows.push(LocRow {
            title: format!("map lamps matched: {}", count_now(|f| f.matched)),
            lines: vec![(&plots.matched, Stroke::new(1.0, LANDMARK))],
            columns: true,
        });
        rows.push(LocRow {
            title: format!("relocalisation hypotheses: {}", count_now(|f| f.hypotheses)),
            lines: vec![(&plots.hypotheses, Stroke::new(1.0, LOST))],
            columns: true,
        });
        ui.label("localisation: localised (blue), lost (pink); fixes (green, dashed)");
        let spacing = ui.spacing().item_spacing;
        let title_height = ui.text_style_height(&egui::TextStyle::Body) + spacing.y;
        let count = rows.len();
        let height =
            ((ui.available_height() - 8.0 - count as f32 * (title_height + 2.0 * spacing.y))
                / count as f32)
                .max(60.0);
        let width = ui.available_width();
        let link = ui.make_persistent_id("stereonav-plots-time");
        let fixes = &plots.fixes_s;
        let mut clicked: Option<f64> = None;
        for (index, row) in rows.iter().enumerate() {
            ui.label(&row.title);
            let plot = time_plot(
                ("stereonav-localization", index),
                [width, height],
                link,
                end,
            )
            .show_x(true)
            .include_y(0.0);
            let response = plot.show(ui, |plot| {
                plot.add(Grid::new(GRID_SPACING.into(), grid_steps));
                for (k, (series, stroke)) in row.lines.iter().enumerate() {
                    let line = ThinLine::new(&format!("{} {k}", row.title), series, *stroke);
                    plot.add(if row.columns { line.columns() } else { line });
                }
                for t in fixes {
                    plot.add(
                        VLine::new("fix", *t)
                            .color(FIX)
                            .width(1.0)
                            .style(LineStyle::dashed_dense()),
                    );
                }
                time_markers(plot, now, None);
            });
            if response.response.clicked()
                && let Some(pos) = response.response.interact_pointer_pos()
            {
                clicked = Some(response.transform.value_from_position(pos).x);
            }
        }
        if let Some(t) = clicked {
            self.set_time(t);
            self.playing = false;
        }
    }

    /// The camera parameters and the NIS over time.
    fn plots(&mut self, ui: &mut Ui) {
        if self.loc_plots.is_some() {
            self.localization_plots(ui);
            return;
        }
        let count = self.params.len() + 1;
        let columns = if count > PLOTS_PER_COLUMN { 2 } else { 1 };
        let rows = count.div_ceil(columns);
        ui.label(format!(
            "camera and vehicle parameters: estimate with its {SIGMAS:.0}-sigma band; NIS against its bound"
        ));
        let spacing = ui.spacing().item_spacing;
        let title_height = ui.text_style_height(&egui::TextStyle::Body) + spacing.y;
        // Each row: its title, the plot, the spacing; a few points spare for rounding.
        let height =
            ((ui.available_height() - 8.0 - rows as f32 * (title_height + 2.0 * spacing.y))
                / rows as f32)
                .max(60.0);
        let width = (ui.available_width() - (columns as f32 - 1.0) * spacing.x) / columns as f32;
        let link = ui.make_persistent_id("stereonav-plots-time");
        let mut clicked: Option<f64> = None;
        let now = self.time_s;
        let switch = self
            .model
            .replay
            .phase_switch_t_us
            .map(|t| self.model.seconds(t));
        let end = self.model.duration_s();
        let t_us = self.model.t_us_at(now);
        let mut index = 0usize;
        let params = &self.params;
        egui::Grid::new("stereonav-plot-grid")
            .num_columns(columns)
            .spacing(spacing)
            .show(ui, |ui| {
                for p in params {
                    ui.vertical(|ui| {
                        ui.set_width(width);
                        let mut title = format!("{} [{}]", p.param.name(), p.unit);
                        if let Some(e) = self.model.param_at(t_us, p.param) {
                            let scale = crate::model::display_unit(p.param).1;
                            let (v, s) = (e.value * scale, e.sigma * scale);
                            title.push_str(&format!(": {v:.4} ± {s:.4}"));
                        }
                        if let Some(t) = p.truth {
                            title.push_str(&format!(" (truth {t:.4})"));
                        }
                        ui.label(title);
                        let response =
                            time_plot(("stereonav-param", index), [width, height], link, end)
                                .show_x(true)
                                .show(ui, |plot| {
                                    plot.add(Grid::new(GRID_SPACING.into(), grid_steps));
                                    if p.value.len() >= 2 {
                                        plot.add(ThinBand::new(
                                            "3 sigma", &p.lower, &p.upper, BAND,
                                        ));
                                    }
                                    plot.add(ThinLine::new(
                                        "estimate",
                                        &p.value,
                                        Stroke::new(1.5, ESTIMATE),
                                    ));
                                    if let Some(t) = p.truth {
                                        plot.add(
                                            HLine::new("truth", t)
                                                .color(TRUTH)
                                                .style(LineStyle::dashed_dense()),
                                        );
                                    }
                                    time_markers(plot, now, switch);
                                });
                        if response.response.clicked()
                            && let Some(pos) = response.response.interact_pointer_pos()
                        {
                            clicked = Some(response.transform.value_from_position(pos).x);
                        }
                    });
                    index += 1;
                    if index.is_multiple_of(columns) {
                        ui.end_row();
                    }
                }
                ui.vertical(|ui| {
                    ui.set_width(width);
                    ui.label(format!(
                        "NIS per dof: frames (dots), last-{} mean (line), {:.1} % bound (red)",
                        self.model.nis.window,
                        vslam_ekf::health::DIVERGENCE_PROBABILITY * 100.0
                    ));
                    let response = time_plot("stereonav-nis", [width, height], link, end)
                        .include_y(0.0)
                        .show(ui, |plot| {
                            plot.add(Grid::new(GRID_SPACING.into(), grid_steps));
                            plot.add(Dots::new(
                                "frame mean",
                                &self.nis_frame,
                                Color32::from_gray(150),
                            ));
                            plot.add(
                                ThinLine::new(
                                    "window mean",
                                    &self.nis_mean,
                                    Stroke::new(1.0, LANDMARK),
                                )
                                .columns(),
                            );
                            plot.add(ThinLine::new(
                                "bound",
                                &self.nis_bound,
                                Stroke::new(1.0, SWITCH),
                            ));
                            plot.add(
                                HLine::new("expected", 1.0)
                                    .color(Color32::from_gray(110))
                                    .style(LineStyle::dashed_dense()),
                            );
                            time_markers(plot, now, switch);
                        });
                    if response.response.clicked()
                        && let Some(pos) = response.response.interact_pointer_pos()
                    {
                        clicked = Some(response.transform.value_from_position(pos).x);
                    }
                });
                ui.end_row();
            });
        if let Some(t) = clicked {
            self.set_time(t);
            self.playing = false;
        }
    }
}

/// Which image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Side {
    Left,
    Right,
}

impl Side {
    fn name(self) -> &'static str {
        match self {
            Self::Left => "left",
            Self::Right => "right",
        }
    }
}

/// A plot over the log's time (0 to `end_s`) of `size` points, its time axis linked to the
/// other plots' by `link`: no background, no scrolling, the viewer's own grid ([`Grid`], at
/// [`grid_steps`], added by the caller) and labels ([`grid_label`]).
fn time_plot<'a>(id: impl egui::AsIdSalt, size: [f32; 2], link: egui::Id, end_s: f64) -> Plot<'a> {
    let [width, height] = size;
    Plot::new(id)
        .height(height)
        .width(width)
        .link_axis(link, [true, false])
        .include_x(0.0)
        .include_x(end_s)
        .allow_scroll(false)
        .show_background(false)
        .grid_spacing(GRID_SPACING)
        .show_grid(false)
        .x_grid_spacer(egui_plot::uniform_grid_spacer(grid_steps))
        .y_grid_spacer(egui_plot::uniform_grid_spacer(grid_steps))
        .x_axis_formatter(grid_label)
        .y_axis_formatter(grid_label)
}

/// The grid steps of a plot's axis: the smallest step of 1, 2 or 5 times a power of ten that
/// is at least `input.base_step_size` (the [`GRID_SPACING`] minimum in axis units), and two
/// coarser steps, each a multiple of the finer (egui_plot's own steps are powers of ten only,
/// which leaves an axis with one label when a decade is just too dense).
fn grid_steps(input: egui_plot::GridInput) -> [f64; 3] {
    let base = input.base_step_size;
    let span = (input.bounds.1 - input.bounds.0).abs();
    // Never more than a few hundred lines, whatever the input.
    let base = if base.is_finite() && base > 0.0 {
        base.max(span / 500.0)
    } else {
        span.max(1.0)
    };
    let s0 = nice_step(base);
    // Each coarser step a multiple of the finer: 1-5-10, 2-10-20, 5-10-50 (times 10^k).
    let mantissa = s0 / 10f64.powf(s0.log10().floor());
    let s1 = if mantissa > 3.0 { 2.0 * s0 } else { 5.0 * s0 };
    [s0, s1, 10.0 * s0]
}

/// The smallest of 1, 2 or 5 times a power of ten that is at least `x` (positive).
fn nice_step(x: f64) -> f64 {
    let decade = 10f64.powf(x.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * decade)
        .find(|s| *s >= x * (1.0 - 1e-9))
        .unwrap_or(10.0 * decade)
}

/// A grid line's label: its value with as many decimals as its step needs (a step of 0.2 or
/// 0.5 needs one).
fn grid_label(mark: egui_plot::GridMark, _range: &std::ops::RangeInclusive<f64>) -> String {
    format!("{:.*}", step_decimals(mark.step_size, 12), mark.value)
}

/// The decimals a value on a grid of `step` needs (0.2 or 0.5: one; 1 or 50: none), at most
/// `most`; none for a step that is not a positive number.
fn step_decimals(step: f64, most: usize) -> usize {
    if step > 0.0 && step.is_finite() {
        ((-step.log10() - 1e-9).ceil().max(0.0) as usize).min(most)
    } else {
        0
    }
}

/// The current time and the phase switch on a plot.
fn time_markers(plot: &mut egui_plot::PlotUi<'_>, now: f64, switch: Option<f64>) {
    if let Some(t) = switch {
        plot.add(
            VLine::new("phase switch", t)
                .color(SWITCH)
                .width(1.5)
                .style(LineStyle::dashed_dense()),
        );
    }
    plot.add(VLine::new("now", now).color(NOW).width(1.0));
}

/// A power of ten that makes the median landmark's ellipse a visible fraction of the run's
/// extent (the ellipses of a good map are millimetres on a map of metres).
fn auto_ellipse_scale(m: &Model) -> f64 {
    let mut axes: Vec<f64> = m
        .replay
        .landmarks
        .iter()
        .map(|l| l.covariance[0][0].max(l.covariance[1][1]).max(0.0).sqrt() * SIGMAS)
        .filter(|a| a.is_finite() && *a > 0.0)
        .collect();
    axes.sort_by(f64::total_cmp);
    let [x0, y0, x1, y1] = m.bounds;
    let extent = (x1 - x0).max(y1 - y0).max(1.0);
    match axes.get(axes.len() / 2) {
        Some(&a) => {
            let k = (0.015 * extent / a).log10().round().clamp(0.0, 4.0);
            10f64.powf(k)
        }
        None => 1.0,
    }
}

/// The outline of the `k`-sigma ellipse of a 2x2 covariance around `centre`, with about one
/// point a screen point of its radius (`m_per_pt`); `None` when the covariance is not finite or
/// the ellipse fits inside the 5-point marker drawn on it.
fn ellipse(centre: [f64; 2], cov: [[f64; 2]; 2], k: f64, m_per_pt: f64) -> Option<Vec<[f64; 2]>> {
    let [[a, b], [_, d]] = cov;
    if ![a, b, d].iter().all(|v| v.is_finite()) {
        return None;
    }
    // Eigen-decomposition of a symmetric 2x2 matrix.
    let mean = (a + d) / 2.0;
    let radius = (((a - d) / 2.0).powi(2) + b * b).sqrt();
    let (l1, l2) = ((mean + radius).max(0.0), (mean - radius).max(0.0));
    let angle = 0.5 * (2.0 * b).atan2(a - d);
    let (s, c) = angle.sin_cos();
    let (r1, r2) = (k * l1.sqrt(), k * l2.sqrt());
    let r1_pt = r1 / m_per_pt;
    if r1_pt.is_nan() || r1_pt < MARKER_HALF_WIDTH {
        return None;
    }
    let segments = (r1_pt.ceil() as usize).clamp(ELLIPSE_MIN_SEGMENTS, ELLIPSE_SEGMENTS);
    Some(
        (0..segments)
            .map(|i| {
                let t = i as f64 / segments as f64 * core::f64::consts::TAU;
                let (x, y) = (r1 * t.cos(), r2 * t.sin());
                [centre[0] + c * x - s * y, centre[1] + s * x + c * y]
            })
            .collect(),
    )
}

/// Grid lines at a round spacing, labelled in metres.
fn grid(painter: &egui::Painter, rect: Rect, view: MapView) {
    let target_pt = 80.0;
    let step = nice_step(view.m_per_pt * target_pt);
    if !(step.is_finite() && step > 0.0) {
        return;
    }
    let half_w = f64::from(rect.width()) / 2.0 * view.m_per_pt;
    let half_h = f64::from(rect.height()) / 2.0 * view.m_per_pt;
    // One-pixel bars on the pixel grid, one mesh (see [`crate::plot_items::Grid`]).
    let mut lines = egui::Mesh::default();
    let colour = Color32::from_gray(40);
    let under_labels = painter.add(Shape::Noop);
    let text = Color32::from_gray(110);
    let font = FontId::proportional(10.0);
    let mut x = ((view.centre[0] - half_w) / step).ceil() * step;
    while x <= view.centre[0] + half_w {
        let sx = rect.center().x + ((x - view.centre[0]) / view.m_per_pt) as f32;
        let px = sx.floor();
        lines.add_colored_rect(
            Rect::from_min_max(pos2(px, rect.top()), pos2(px + 1.0, rect.bottom())),
            colour,
        );
        painter.text(
            pos2(sx + 2.0, rect.bottom() - 2.0),
            Align2::LEFT_BOTTOM,
            format_m(x, step),
            font.clone(),
            text,
        );
        x += step;
    }
    let mut y = ((view.centre[1] - half_h) / step).ceil() * step;
    while y <= view.centre[1] + half_h {
        let sy = rect.center().y - ((y - view.centre[1]) / view.m_per_pt) as f32;
        let py = sy.floor();
        lines.add_colored_rect(
            Rect::from_min_max(pos2(rect.left(), py), pos2(rect.right(), py + 1.0)),
            colour,
        );
        painter.text(
            pos2(rect.left() + 2.0, sy - 2.0),
            Align2::LEFT_BOTTOM,
            format_m(y, step),
            font.clone(),
            text,
        );
        y += step;
    }
    painter.set(under_labels, lines);
}

/// A grid label: `v` metres with as many decimals as the grid `step` needs.
fn format_m(v: f64, step: f64) -> String {
    let decimals = step_decimals(step, 6);
    let v = if v.abs() < step * 1e-6 { 0.0 } else { v };
    format!("{v:.decimals$} m")
}

/// The map's colour key, top left (a localisation run's when `localization`); returns where
/// it was drawn.
fn legend(painter: &egui::Painter, rect: Rect, truth: bool, localization: bool) -> Rect {
    let mut entries = if localization {
        vec![
            (TRAJECTORY, "localised: trajectory and robot", Mark::Dot),
            (LOST, "lost: the localiser's best guess", Mark::Dot),
            (LANDMARK, "map lamp", Mark::Square),
            (MISSING, "map lamp reported missing", Mark::Ring),
            (NEW_LAMP, "new lamp, not in the map", Mark::Cross),
            (ELLIPSE, "uncertainty ellipse", Mark::Dot),
        ]
    } else {
        vec![
            (TRAJECTORY, "estimated trajectory and robot", Mark::Dot),
            (LANDMARK, "landmark", Mark::Square),
            (UPDATED, "landmark updated at this frame", Mark::Square),
            (ELLIPSE, "uncertainty ellipse", Mark::Dot),
        ]
    };
    entries.extend([
        (FOV[0], "left camera's view on the lamp plane", Mark::Dot),
        (FOV[1], "right camera's view", Mark::Dot),
    ]);
    if truth {
        entries.push((TRUTH, "truth: trajectory, lamps (+)", Mark::Plus));
    }
    let font = FontId::proportional(11.0);
    let line = 14.0;
    let size = Vec2::new(230.0, line * entries.len() as f32 + 8.0);
    let frame = Rect::from_min_size(rect.left_top() + vec2(8.0, 8.0), size);
    painter.rect_filled(frame, 3.0, Color32::from_rgba_premultiplied(0, 0, 0, 170));
    let mut keys = egui::Mesh::default();
    for (k, (colour, text, mark)) in entries.iter().enumerate() {
        let y = frame.top() + 4.0 + line * k as f32 + line / 2.0;
        let at = pos2(frame.left() + 10.0, y);
        match mark {
            Mark::Dot => {
                painter.circle_filled(at, 4.0, *colour);
            }
            Mark::Square => square_marker(&mut keys, at, *colour),
            Mark::Plus => plus_marker(&mut keys, at, *colour),
            Mark::Ring => {
                painter.circle_stroke(at, 4.5, Stroke::new(1.5, *colour));
            }
            Mark::Cross => cross(painter, at, *colour),
        }
        painter.text(
            pos2(frame.left() + 20.0, y),
            Align2::LEFT_CENTER,
            *text,
            font.clone(),
            Color32::from_gray(210),
        );
    }
    painter.add(keys);
    frame
}

/// How a legend entry shows its colour.
#[derive(Debug, Clone, Copy)]
enum Mark {
    Dot,
    Square,
    Plus,
    Ring,
    Cross,
}

/// A diagonal cross at `at` (a new lamp: few, so two anti-aliased strokes).
fn cross(painter: &egui::Painter, at: Pos2, colour: Color32) {
    let (d, e) = (
        vec2(CROSS_HALF_WIDTH, CROSS_HALF_WIDTH),
        vec2(CROSS_HALF_WIDTH, -CROSS_HALF_WIDTH),
    );
    let stroke = Stroke::new(1.5, colour);
    painter.line_segment([at - d, at + d], stroke);
    painter.line_segment([at - e, at + e], stroke);
}

/// A file's name for display (the whole path when it has none).
fn file_name(path: &std::path::Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

/// What a localisation run's frame says, and its colour: localised (with the lamps matched) or
/// lost (with the hypotheses alive).
fn localization_status(frame: Option<&replay::LocalizedFrame>) -> (String, Color32) {
    match frame {
        None => ("no frames".to_string(), Color32::from_gray(160)),
        Some(f) if f.localized => (
            format!("localised: {} map lamps matched", f.matched),
            TRAJECTORY,
        ),
        Some(f) => (
            format!(
                "lost: {} hypothes{}{}{}",
                f.hypotheses,
                if f.hypotheses == 1 { "is" } else { "es" },
                if f.pose.is_some() { "" } else { ", no pose" },
                f.waiting
                    .map_or(String::new(), |w| format!("; waiting: {w}"))
            ),
            LOST,
        ),
    }
}

/// A 5x5-pixel square at `at`, aligned to the pixel grid, added to `mesh`: two triangles
/// without anti-aliasing (a map draws hundreds of them each frame; see [`crate::thin`]).
fn square_marker(mesh: &mut egui::Mesh, at: Pos2, colour: Color32) {
    let (x, y) = (at.x.floor(), at.y.floor());
    mesh.add_colored_rect(
        Rect::from_min_max(pos2(x - 2.0, y - 2.0), pos2(x + 3.0, y + 3.0)),
        colour,
    );
}

/// A 7-pixel plus at `at`, aligned to the pixel grid, added to `mesh`: two one-pixel bars,
/// four triangles without anti-aliasing (a map draws hundreds of them each frame).
fn plus_marker(mesh: &mut egui::Mesh, at: Pos2, colour: Color32) {
    let (x, y) = (at.x.floor(), at.y.floor());
    mesh.add_colored_rect(
        Rect::from_min_max(pos2(x - 3.0, y), pos2(x + 4.0, y + 1.0)),
        colour,
    );
    mesh.add_colored_rect(
        Rect::from_min_max(pos2(x, y - 3.0), pos2(x + 1.0, y)),
        colour,
    );
    mesh.add_colored_rect(
        Rect::from_min_max(pos2(x, y + 1.0), pos2(x + 1.0, y + 4.0)),
        colour,
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    fn steps(lo: f64, hi: f64, base: f64) -> [f64; 3] {
        grid_steps(egui_plot::GridInput {
            bounds: (lo, hi),
            base_step_size: base,
        })
    }

    #[test]
    fn a_lost_frame_says_what_holds_the_fix_back() {
        let frame = replay::LocalizedFrame {
            t_us: 1,
            pose: Some([1.0, 2.0, 0.3]),
            sigma: [0.1; 3],
            localized: false,
            matched: 0,
            hypotheses: 2,
            truth: None,
            waiting: Some(replay::Waiting::Margin { ahead_nats: 12.5 }),
            weighed: [None; replay::WEIGHED_SHOWN],
            generation: None,
        };
        let (text, colour) = localization_status(Some(&frame));
        assert_eq!(colour, LOST);
        assert!(text.starts_with("lost: 2 hypotheses"), "{text}");
        assert!(text.contains("12.5 nats ahead"), "{text}");
        let localized = replay::LocalizedFrame {
            localized: true,
            matched: 7,
            waiting: None,
            ..frame
        };
        assert_eq!(
            localization_status(Some(&localized)).0,
            "localised: 7 map lamps matched"
        );
    }

    #[test]
    fn grid_steps_are_nice_and_nested() {
        assert_eq!(steps(118.4, 119.8, 0.11), [0.2, 1.0, 2.0]);
        assert_eq!(steps(0.0, 3.0, 0.3), [0.5, 1.0, 5.0]);
        assert_eq!(steps(0.0, 240.0, 9.0), [10.0, 50.0, 100.0]);
        for [s0, s1, s2] in [steps(0.0, 1.0, 0.013), steps(-5.0, 5.0, 0.7)] {
            assert!(((s1 / s0) - (s1 / s0).round()).abs() < 1e-9);
            assert!(((s2 / s1) - (s2 / s1).round()).abs() < 1e-9);
        }
        // Degenerate input gives a few lines, never millions.
        let [s0, ..] = steps(0.0, 1e6, 1e-12);
        assert!(1e6 / s0 <= 1000.0);
        assert!(
            steps(0.0, 1.0, f64::NAN)
                .iter()
                .all(|s| s.is_finite() && *s > 0.0)
        );
    }

    #[test]
    fn grid_labels_have_the_decimals_their_step_needs() {
        let label = |value: f64, step_size: f64| {
            grid_label(egui_plot::GridMark { value, step_size }, &(0.0..=1.0))
        };
        assert_eq!(label(119.4, 0.2), "119.4");
        assert_eq!(label(119.5, 0.5), "119.5");
        assert_eq!(label(119.0, 1.0), "119");
        assert_eq!(label(0.05, 0.05), "0.05");
        assert_eq!(label(200.0, 50.0), "200");
        // The map's labels: metres on steps of 1, 2 or 5 times a power of ten, at most 6.
        assert_eq!(format_m(0.4, 0.2), "0.4 m");
        assert_eq!(format_m(-10.0, 10.0), "-10 m");
        assert_eq!(format_m(1e-12, 0.001), "0.000 m");
        assert_eq!(step_decimals(1e-9, 6), 6);
        assert_eq!(step_decimals(f64::NAN, 6), 0);
    }
}
