//! The stereonav viewer (`stereonav view`): a vehicle log replayed through the stack, or
//! localised on a saved map ([`LoadOptions::map`], [`model::Localization`]), or an estimates
//! file written by `stereonav replay`, shown in egui.
//!
//! - **Images**: the left and right image planes with the board's features at the current
//!   frame, marked by the navigator's own associations (`FrameEstimate::associations`), and
//!   the landmarks' projections, taken through the rig's lenses when it has them so that both
//!   are in the board's raw pixels ([`Model::marks`]). Under them, for a ROS 2 bag, the camera
//!   images of the frame (the raw images the host's detector ran on), read back from the bag
//!   on demand through an index built at load time, a few frames cached ([`images`]); the
//!   board's stream carries no images, and its planes are drawn empty.
//! - **Map**: the trajectory (estimate, and the simulator's truth when the log has it), the
//!   landmarks with their 3-sigma covariance ellipses, the robot with its pose ellipse, and
//!   the two cameras' fields of view on the lamp plane.
//! - **Plots** over time: every estimated camera parameter with its 3-sigma band and the phase
//!   switch marked (the paper's Figs. 4, 5, 9), and the NIS against its bound.
//! - **Timeline**: scrub, play, step frame by frame.
//!
//! A localisation run is shown in the same panels: its status (localised, or lost with the
//! hypotheses alive) in the header and on a strip under the timeline, the trajectory coloured
//! by status, the map's missing lamps ringed and the new lamps crossed, and plots of the pose's
//! uncertainty, the lamps matched and the hypotheses in place of the camera parameters.
//!
//! The data model ([`model`]) is plain data computed once at load time ([`load`]); the drawing
//! ([`Viewer::ui`]) costs what one frame shows. The same drawing runs in a window
//! ([`run_window`], eframe on OpenGL) and headless ([`Headless`], [`screenshot`]): egui's
//! output rasterised on the CPU by [`raster::SoftwareRenderer`], with no GPU, driver or
//! display.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

mod error;
pub mod images;
mod load;
pub mod model;
pub mod plot_items;
pub mod raster;
pub mod thin;
mod ui;

use std::path::Path;

pub use error::Error;
pub use load::{LoadOptions, load};
pub use model::Model;
pub use raster::{FillEstimate, Frame, SoftwareRenderer, fill_estimate};
pub use ui::{Regions, Viewer, background, image_to_screen};

/// The smallest screenshot, pixels (the fixed size).
pub const MIN_SCREENSHOT_SIZE: [u32; 2] = [1280, 800];

/// The largest side of a screenshot, pixels.
pub const MAX_SCREENSHOT_SIDE: u32 = 4096;

/// egui passes run before a screenshot is taken: the first lays out and measures, the next
/// draw with the sizes known.
const SETTLE_PASSES: usize = 3;

/// The viewer without a window: egui driven by hand at a fixed size, its output tessellated
/// and, on request, rasterised on the CPU.
#[derive(Debug)]
pub struct Headless {
    ctx: egui::Context,
    renderer: SoftwareRenderer,
    viewer: Viewer,
    size: [u32; 2],
    time: f64,
    last: Option<(Vec<egui::ClippedPrimitive>, f32)>,
}

impl Headless {
    /// `viewer` at `width x height` points, one pixel a point, egui's dark theme.
    pub fn new(viewer: Viewer, size: [u32; 2]) -> Self {
        let ctx = egui::Context::default();
        ctx.set_theme(egui::Theme::Dark);
        Self {
            ctx,
            renderer: SoftwareRenderer::new(),
            viewer,
            size,
            time: 0.0,
            last: None,
        }
    }

    /// The viewer.
    pub fn viewer(&self) -> &Viewer {
        &self.viewer
    }

    /// The viewer, to move its time.
    pub fn viewer_mut(&mut self) -> &mut Viewer {
        &mut self.viewer
    }

    /// One egui pass of the viewer and the tessellation of its shapes: the work of one frame
    /// in the window, short of the GPU's painting. Returns the triangles drawn.
    pub fn run_frame(&mut self) -> usize {
        let [w, h] = self.size;
        self.time += 1.0 / 60.0;
        let mut input = egui::RawInput {
            screen_rect: Some(egui::Rect::from_min_size(
                egui::Pos2::ZERO,
                egui::vec2(w as f32, h as f32),
            )),
            time: Some(self.time),
            predicted_dt: 1.0 / 60.0,
            ..Default::default()
        };
        if let Some(viewport) = input.viewports.get_mut(&egui::ViewportId::ROOT) {
            viewport.native_pixels_per_point = Some(1.0);
        }
        let viewer = &mut self.viewer;
        let egui::FullOutput {
            mut textures_delta,
            shapes,
            pixels_per_point,
            ..
        } = self.ctx.run_ui(input, |ui| viewer.ui(ui));
        self.renderer.set_textures(&textures_delta);
        let primitives = self.ctx.tessellate(shapes, pixels_per_point);
        self.renderer.free(&textures_delta);
        // Handled: egui checks that no texture update is dropped unapplied.
        textures_delta.clear();
        let triangles = primitives
            .iter()
            .map(|p| match &p.primitive {
                egui::epaint::Primitive::Mesh(m) => m.indices.len() / 3,
                egui::epaint::Primitive::Callback(_) => 0,
            })
            .sum();
        self.last = Some((primitives, pixels_per_point));
        triangles
    }

    /// What the last frame ([`Headless::run_frame`]) asks of a software OpenGL renderer
    /// ([`raster::fill_estimate`]); `None` before the first frame.
    pub fn fill_estimate(&self) -> Option<FillEstimate> {
        self.last
            .as_ref()
            .map(|(primitives, ppp)| fill_estimate(primitives, *ppp))
    }

    /// Rasterises the last frame ([`Headless::run_frame`]; one is run first if there is
    /// none).
    pub fn render(&mut self) -> Frame {
        if self.last.is_none() {
            self.run_frame();
        }
        let [w, h] = self.size;
        let clear = background(&self.ctx.global_style().visuals);
        match &self.last {
            Some((primitives, ppp)) => self.renderer.paint(primitives, w, h, *ppp, clear),
            None => self.renderer.paint(&[], w, h, 1.0, clear),
        }
    }
}

/// A screenshot: the image and where the viewer's parts are in it.
#[derive(Debug, Clone)]
pub struct Screenshot {
    /// The image.
    pub frame: Frame,
    /// Where the parts were drawn, pixels.
    pub regions: Regions,
}

/// The viewer of `model` at `time_s` seconds from the log's start (the end when `None`),
/// rendered headless at `size` pixels.
///
/// Errors: a size below [`MIN_SCREENSHOT_SIZE`] or above [`MAX_SCREENSHOT_SIDE`], or a time
/// outside the log.
pub fn screenshot(model: Model, time_s: Option<f64>, size: [u32; 2]) -> Result<Screenshot, Error> {
    check_size(size)?;
    let mut viewer = Viewer::new(model);
    if let Some(t) = time_s {
        check_time(viewer.model(), t)?;
        viewer.set_time(t);
    }
    let mut headless = Headless::new(viewer, size);
    for _ in 0..SETTLE_PASSES {
        headless.run_frame();
    }
    let frame = headless.render();
    Ok(Screenshot {
        frame,
        regions: headless.viewer().regions(),
    })
}

/// Writes a rendered frame as PNG.
pub fn write_png(path: &Path, frame: &Frame) -> Result<(), Error> {
    image::save_buffer_with_format(
        path,
        &frame.rgba,
        frame.width,
        frame.height,
        image::ExtendedColorType::Rgba8,
        image::ImageFormat::Png,
    )
    .map_err(|source| Error::Png {
        path: path.to_path_buf(),
        source,
    })
}

/// Checks a screenshot size against [`MIN_SCREENSHOT_SIZE`] and [`MAX_SCREENSHOT_SIDE`].
pub fn check_size(size: [u32; 2]) -> Result<(), Error> {
    let [w, h] = size;
    let [min_w, min_h] = MIN_SCREENSHOT_SIZE;
    if w < min_w || h < min_h || w > MAX_SCREENSHOT_SIDE || h > MAX_SCREENSHOT_SIDE {
        return Err(Error::BadSize {
            width: w,
            height: h,
            min_width: min_w,
            min_height: min_h,
            max: MAX_SCREENSHOT_SIDE,
        });
    }
    Ok(())
}

/// Checks that `time_s` lies in the log.
pub fn check_time(model: &Model, time_s: f64) -> Result<(), Error> {
    let end_s = model.duration_s();
    if !(time_s.is_finite() && time_s >= 0.0 && time_s <= end_s + 1e-9) {
        return Err(Error::TimeOutsideLog { time_s, end_s });
    }
    Ok(())
}

/// Whether a window can be tried: on Linux, `DISPLAY` or `WAYLAND_DISPLAY` must be set
/// ([`Error::NoDisplay`] otherwise). A caller checks it before a long replay.
pub fn check_display() -> Result<(), Error> {
    let display = |name: &str| std::env::var_os(name).is_some_and(|v| !v.is_empty());
    if cfg!(target_os = "linux") && !display("DISPLAY") && !display("WAYLAND_DISPLAY") {
        return Err(Error::NoDisplay);
    }
    Ok(())
}

/// The viewer in a window (eframe on OpenGL under X11), until it is closed.
///
/// Errors: no display ([`Error::NoDisplay`]: neither `DISPLAY` nor `WAYLAND_DISPLAY` set), or
/// the window or its OpenGL context could not be made ([`Error::Window`]).
pub fn run_window(viewer: Viewer) -> Result<(), Error> {
    check_display()?;
    let title = format!(
        "stereonav view: {}",
        viewer
            .model()
            .path
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
    );
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_inner_size([1400.0, 900.0])
            .with_min_inner_size([800.0, 500.0])
            .with_title(title.clone()),
        renderer: eframe::Renderer::Glow,
        ..Default::default()
    };
    eframe::run_native(
        &title,
        options,
        Box::new(move |cc| {
            cc.egui_ctx.set_theme(egui::Theme::Dark);
            Ok(Box::new(Window { viewer }))
        }),
    )
    .map_err(|e| Error::Window {
        display: std::env::var("DISPLAY").unwrap_or_default(),
        detail: e
            .to_string()
            .lines()
            .map(str::trim)
            .collect::<Vec<_>>()
            .join(" "),
    })
}

/// The eframe application: the viewer, drawn each frame.
#[derive(Debug)]
struct Window {
    viewer: Viewer,
}

impl eframe::App for Window {
    fn clear_color(&self, visuals: &egui::Visuals) -> [f32; 4] {
        background(visuals).to_normalized_gamma_f32()
    }

    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        self.viewer.ui(ui);
    }
}
