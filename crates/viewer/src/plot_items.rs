//! egui_plot items that draw only what the plot's pixels can show (see [`crate::thin`]).
//!
//! egui_plot's own `Line`, `FilledArea` and `Points` hand every sample to the tessellator each
//! frame: thousands of thin, anti-aliased triangles for a run of a few minutes, which software
//! OpenGL fills 4x4 pixels at a time. These items keep the whole series for the plot's bounds
//! and hover, and thin it with the transform of the frame being drawn:
//!
//! - [`ThinLine`]: the visible samples, the lowest and highest of each pixel column, then
//!   simplified to [`thin::TOLERANCE_PX`]; or, for a noisy series denser than the pixels, one
//!   bar a pixel column ([`ThinLine::columns`]);
//! - [`ThinBand`]: a filled band between two series, thinned the same way, drawn as one mesh of
//!   strips without anti-aliasing (a translucent band shows no edge to smooth);
//! - [`Dots`]: one 3x3-pixel square per occupied pixel, one mesh.

use std::ops::RangeInclusive;

use egui::{Color32, Mesh, Pos2, Rect, Shape, Stroke, Ui, pos2, vec2};
use egui_plot::{PlotBounds, PlotGeometry, PlotItem, PlotItemBase, PlotPoint, PlotTransform};

use crate::thin;

/// A series, `x` ascending, with its bounds.
#[derive(Debug, Clone)]
pub struct Series {
    points: Vec<PlotPoint>,
    bounds: PlotBounds,
}

impl Series {
    /// A series of `[x, y]` (x ascending); non-finite values are kept (they break a line) but
    /// do not count in the bounds.
    pub fn new(points: impl IntoIterator<Item = [f64; 2]>) -> Self {
        let points: Vec<PlotPoint> = points
            .into_iter()
            .map(|[x, y]| PlotPoint::new(x, y))
            .collect();
        let mut bounds = PlotBounds::NOTHING;
        for p in &points {
            if p.x.is_finite() && p.y.is_finite() {
                bounds.extend_with(p);
            }
        }
        Self { points, bounds }
    }

    /// The samples.
    pub fn points(&self) -> &[PlotPoint] {
        &self.points
    }

    /// How many samples.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
}

/// The indices of `series` a plot with `transform` draws: see [`thin::column_extremes`].
fn visible_extremes(series: &[PlotPoint], transform: &PlotTransform) -> Vec<usize> {
    let frame = transform.frame();
    thin::column_extremes(
        series,
        |p| [p.x, p.y],
        |x| f64::from(transform.position_from_point_x(x)),
        f64::from(frame.left()) - 1.0,
        f64::from(frame.right()) + 1.0,
    )
}

/// The screen positions of `series[idx]`, as pixels for [`thin::simplify`].
fn screen(series: &[PlotPoint], idx: &[usize], transform: &PlotTransform) -> Vec<[f32; 2]> {
    idx.iter()
        .map(|k| {
            series.get(*k).map_or([f32::NAN; 2], |p| {
                let s = transform.position_from_point(p);
                [s.x, s.y]
            })
        })
        .collect()
}

/// A line through a [`Series`], thinned to the pixels each frame.
#[derive(Debug)]
pub struct ThinLine<'a> {
    base: PlotItemBase,
    series: &'a Series,
    stroke: Stroke,
    columns: bool,
}

impl<'a> ThinLine<'a> {
    /// `series` drawn with `stroke`.
    pub fn new(name: &str, series: &'a Series, stroke: Stroke) -> Self {
        Self {
            base: PlotItemBase::new(name.to_owned()),
            series,
            stroke,
            columns: false,
        }
    }

    /// Draws the line as one-pixel columns, each from the lowest to the highest point the
    /// line reaches in it (joined to the column before), where the series has more samples
    /// than the plot has pixel columns: the same pixels as a one-pixel line through a noisy
    /// series, at two triangles a column instead of a few thin ones a sample.
    pub fn columns(mut self) -> Self {
        self.columns = true;
        self
    }

    /// The line as columns (see [`ThinLine::columns`]); `px` are the visible samples on the
    /// screen, in order.
    fn column_mesh(&self, px: &[[f32; 2]]) -> Mesh {
        let mut mesh = Mesh::default();
        let mut column: Option<(f32, f32, f32)> = None;
        let mut last_y: Option<f32> = None;
        let flush = |mesh: &mut Mesh, c: Option<(f32, f32, f32)>| {
            if let Some((x, lo, hi)) = c {
                mesh.add_colored_rect(
                    Rect::from_min_max(pos2(x, lo.floor()), pos2(x + 1.0, hi.floor() + 1.0)),
                    self.stroke.color,
                );
            }
        };
        for p in px {
            if !(p[0].is_finite() && p[1].is_finite()) {
                flush(&mut mesh, column.take());
                last_y = None;
                continue;
            }
            let x = p[0].floor();
            match column {
                Some((cx, lo, hi)) if cx == x => column = Some((cx, lo.min(p[1]), hi.max(p[1]))),
                _ => {
                    flush(&mut mesh, column.take());
                    // Joined to the column before: from its last point to this one.
                    let from = last_y.unwrap_or(p[1]);
                    column = Some((x, from.min(p[1]), from.max(p[1])));
                }
            }
            last_y = Some(p[1]);
        }
        flush(&mut mesh, column);
        mesh
    }
}

impl PlotItem for ThinLine<'_> {
    fn shapes(&self, _ui: &Ui, transform: &PlotTransform, shapes: &mut Vec<Shape>) {
        let points = self.series.points();
        let idx = visible_extremes(points, transform);
        let px = screen(points, &idx, transform);
        let frame = transform.frame();
        if self.columns && idx.len() as f32 > frame.width() {
            let mesh = self.column_mesh(&px);
            if !mesh.is_empty() {
                shapes.push(Shape::mesh(mesh));
            }
            return;
        }
        // Non-finite samples break the line: draw each finite run on its own.
        let mut run: Vec<Pos2> = Vec::new();
        for k in thin::simplify(&px, thin::TOLERANCE_PX, &[]) {
            match px.get(k) {
                Some(p) if p[0].is_finite() && p[1].is_finite() => run.push(pos2(p[0], p[1])),
                _ => {
                    if run.len() >= 2 {
                        shapes.push(Shape::line(std::mem::take(&mut run), self.stroke));
                    }
                    run.clear();
                }
            }
        }
        if run.len() >= 2 {
            shapes.push(Shape::line(run, self.stroke));
        }
    }

    fn initialize(&mut self, _x_range: RangeInclusive<f64>) {}

    fn color(&self) -> Color32 {
        self.stroke.color
    }

    fn geometry(&self) -> PlotGeometry<'_> {
        PlotGeometry::Points(self.series.points())
    }

    fn bounds(&self) -> PlotBounds {
        self.series.bounds
    }

    fn base(&self) -> &PlotItemBase {
        &self.base
    }

    fn base_mut(&mut self) -> &mut PlotItemBase {
        &mut self.base
    }
}

/// A band filled between two series sampled at the same `x` (a 3-sigma band).
#[derive(Debug)]
pub struct ThinBand<'a> {
    base: PlotItemBase,
    lower: &'a Series,
    upper: &'a Series,
    fill: Color32,
}

impl<'a> ThinBand<'a> {
    /// The band from `lower` to `upper` (same `x`, same length), filled with `fill`.
    pub fn new(name: &str, lower: &'a Series, upper: &'a Series, fill: Color32) -> Self {
        Self {
            base: PlotItemBase::new(name.to_owned()),
            lower,
            upper,
            fill,
        }
    }
}

impl PlotItem for ThinBand<'_> {
    fn shapes(&self, _ui: &Ui, transform: &PlotTransform, shapes: &mut Vec<Shape>) {
        let (lower, upper) = (self.lower.points(), self.upper.points());
        let n = lower.len().min(upper.len());
        let (lower, upper) = (lower.get(..n).unwrap_or(&[]), upper.get(..n).unwrap_or(&[]));
        // Where either edge reaches a column's extreme, then where either edge bends.
        let mut idx = visible_extremes(lower, transform);
        idx.extend(visible_extremes(upper, transform));
        idx.sort_unstable();
        idx.dedup();
        let (lo, hi) = (
            screen(lower, &idx, transform),
            screen(upper, &idx, transform),
        );
        let mut keep = thin::simplify(&lo, thin::TOLERANCE_PX, &[]);
        keep.extend(thin::simplify(&hi, thin::TOLERANCE_PX, &[]));
        keep.sort_unstable();
        keep.dedup();
        let mut mesh = Mesh::default();
        let corner = |v: &[[f32; 2]], k: usize| v.get(k).map(|p| pos2(p[0], p[1]));
        for w in keep.windows(2) {
            let (Some(&a), Some(&b)) = (w.first(), w.get(1)) else {
                continue;
            };
            let (Some(la), Some(ha), Some(lb), Some(hb)) = (
                corner(&lo, a),
                corner(&hi, a),
                corner(&lo, b),
                corner(&hi, b),
            ) else {
                continue;
            };
            if ![la, ha, lb, hb].iter().all(|p| p.is_finite()) {
                continue;
            }
            let first = mesh.vertices.len() as u32;
            for p in [la, ha, hb, lb] {
                mesh.colored_vertex(p, self.fill);
            }
            mesh.add_triangle(first, first + 1, first + 2);
            mesh.add_triangle(first, first + 2, first + 3);
        }
        if !mesh.is_empty() {
            shapes.push(Shape::mesh(mesh));
        }
    }

    fn initialize(&mut self, _x_range: RangeInclusive<f64>) {}

    fn color(&self) -> Color32 {
        self.fill
    }

    fn allow_hover(&self) -> bool {
        false
    }

    fn geometry(&self) -> PlotGeometry<'_> {
        PlotGeometry::None
    }

    fn bounds(&self) -> PlotBounds {
        let mut b = self.lower.bounds;
        b.merge(&self.upper.bounds);
        b
    }

    fn base(&self) -> &PlotItemBase {
        &self.base
    }

    fn base_mut(&mut self) -> &mut PlotItemBase {
        &mut self.base
    }
}

/// A dot for each sample of a series: 3x3-pixel squares, one per occupied pixel.
#[derive(Debug)]
pub struct Dots<'a> {
    base: PlotItemBase,
    series: &'a Series,
    colour: Color32,
}

impl<'a> Dots<'a> {
    /// `series` as dots of `colour`.
    pub fn new(name: &str, series: &'a Series, colour: Color32) -> Self {
        Self {
            base: PlotItemBase::new(name.to_owned()),
            series,
            colour,
        }
    }
}

impl PlotItem for Dots<'_> {
    fn shapes(&self, _ui: &Ui, transform: &PlotTransform, shapes: &mut Vec<Shape>) {
        let frame = transform.frame();
        let points = self.series.points();
        let (left, right) = (frame.left() - 2.0, frame.right() + 2.0);
        let begin = points.partition_point(|p| transform.position_from_point_x(p.x) < left);
        let end = points.partition_point(|p| transform.position_from_point_x(p.x) <= right);
        let mut seen = std::collections::HashSet::new();
        let mut mesh = Mesh::default();
        for p in points.get(begin..end.max(begin)).unwrap_or_default() {
            let s = transform.position_from_point(p);
            if !s.is_finite() {
                continue;
            }
            let (x, y) = (s.x.floor(), s.y.floor());
            if seen.insert((x as i32, y as i32)) {
                mesh.add_colored_rect(
                    Rect::from_min_size(pos2(x - 1.0, y - 1.0), vec2(3.0, 3.0)),
                    self.colour,
                );
            }
        }
        if !mesh.is_empty() {
            shapes.push(Shape::mesh(mesh));
        }
    }

    fn initialize(&mut self, _x_range: RangeInclusive<f64>) {}

    fn color(&self) -> Color32 {
        self.colour
    }

    fn geometry(&self) -> PlotGeometry<'_> {
        PlotGeometry::Points(self.series.points())
    }

    fn bounds(&self) -> PlotBounds {
        self.series.bounds
    }

    fn base(&self) -> &PlotItemBase {
        &self.base
    }

    fn base_mut(&mut self) -> &mut PlotItemBase {
        &mut self.base
    }
}

/// A plot's grid lines, drawn as one-pixel bars on the pixel grid (egui_plot's own grid is
/// anti-aliased segments: three or four long thin triangles a line). The steps come from
/// `steps` (the same the plot's axes use for their labels), faded in over `spacing` points as
/// egui_plot fades its own.
pub struct Grid {
    base: PlotItemBase,
    spacing: egui::Rangef,
    steps: fn(egui_plot::GridInput) -> [f64; 3],
}

impl std::fmt::Debug for Grid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Grid")
            .field("spacing", &self.spacing)
            .finish_non_exhaustive()
    }
}

impl Grid {
    /// Grid lines at `steps`, shown from `spacing.min` points apart, full strength from
    /// `spacing.max`.
    pub fn new(spacing: egui::Rangef, steps: fn(egui_plot::GridInput) -> [f64; 3]) -> Self {
        Self {
            base: PlotItemBase::new("grid".to_owned()),
            spacing,
            steps,
        }
    }
}

impl PlotItem for Grid {
    fn shapes(&self, ui: &Ui, transform: &PlotTransform, shapes: &mut Vec<Shape>) {
        let frame = *transform.frame();
        let bounds = transform.bounds();
        let base_colour = ui.visuals().text_color();
        let mut mesh = Mesh::default();
        for axis in 0..2 {
            let dpos = transform.dpos_dvalue()[axis].abs();
            let (lo, hi) = (bounds.min()[axis], bounds.max()[axis]);
            if !(dpos.is_finite() && dpos > 0.0 && lo.is_finite() && hi.is_finite()) {
                continue;
            }
            let mut steps = (self.steps)(egui_plot::GridInput {
                bounds: (lo, hi),
                base_step_size: f64::from(self.spacing.min) / dpos,
            });
            // Largest first: a value on a coarse step is drawn once, at that step's strength.
            steps.sort_by(|a, b| b.total_cmp(a));
            let mut drawn: Vec<f64> = Vec::new();
            for step in steps {
                let spacing_pt = (dpos * step) as f32;
                if !(step > 0.0 && spacing_pt > self.spacing.min) || (hi - lo) / step > 1000.0 {
                    continue;
                }
                let strength = egui::remap_clamp(spacing_pt, self.spacing, 0.0..=1.0);
                let colour = base_colour.gamma_multiply(strength.sqrt());
                let first = (lo / step).ceil() as i64;
                let last = (hi / step).floor() as i64;
                for k in first..=last {
                    let value = k as f64 * step;
                    if drawn.iter().any(|d| (d - value).abs() < step * 1e-6) {
                        continue;
                    }
                    drawn.push(value);
                    let at = if axis == 0 {
                        transform.position_from_point_x(value)
                    } else {
                        transform.position_from_point_y(value)
                    };
                    let px = at.floor();
                    let bar = if axis == 0 {
                        Rect::from_min_max(pos2(px, frame.top()), pos2(px + 1.0, frame.bottom()))
                    } else {
                        Rect::from_min_max(pos2(frame.left(), px), pos2(frame.right(), px + 1.0))
                    };
                    mesh.add_colored_rect(bar, colour);
                }
            }
            drawn.clear();
        }
        if !mesh.is_empty() {
            shapes.push(Shape::mesh(mesh));
        }
    }

    fn initialize(&mut self, _x_range: RangeInclusive<f64>) {}

    fn color(&self) -> Color32 {
        Color32::GRAY
    }

    fn allow_hover(&self) -> bool {
        false
    }

    fn geometry(&self) -> PlotGeometry<'_> {
        PlotGeometry::None
    }

    fn bounds(&self) -> PlotBounds {
        PlotBounds::NOTHING
    }

    fn base(&self) -> &PlotItemBase {
        &self.base
    }

    fn base_mut(&mut self) -> &mut PlotItemBase {
        &mut self.base
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]

    use super::*;

    #[test]
    fn columns_cover_each_pixel_column_from_its_lowest_to_its_highest_point() {
        let series = Series::new([[0.0, 0.0], [1.0, 1.0]]);
        let line = ThinLine::new("l", &series, Stroke::new(1.0, Color32::RED)).columns();
        // Column 10: 5.2 .. 8.9; column 11: joined from 8.9 down to 3.1; a break; column 13.
        let px = [
            [10.2, 5.2],
            [10.6, 8.9],
            [11.5, 3.1],
            [f32::NAN, 0.0],
            [13.0, 7.0],
        ];
        let mesh = line.column_mesh(&px);
        let rects: Vec<Rect> = mesh
            .vertices
            .chunks(4)
            .map(|q| Rect::from_points(&q.iter().map(|v| v.pos).collect::<Vec<_>>()))
            .collect();
        assert_eq!(
            rects,
            vec![
                Rect::from_min_max(pos2(10.0, 5.0), pos2(11.0, 9.0)),
                Rect::from_min_max(pos2(11.0, 3.0), pos2(12.0, 9.0)),
                Rect::from_min_max(pos2(13.0, 7.0), pos2(14.0, 8.0)),
            ]
        );
        assert!(mesh.vertices.iter().all(|v| v.color == Color32::RED));
    }

    #[test]
    fn series_bounds_skip_non_finite_samples() {
        let s = Series::new([[0.0, 1.0], [1.0, f64::NAN], [2.0, -3.0]]);
        assert_eq!(s.len(), 3);
        assert_eq!(s.bounds.min(), [0.0, -3.0]);
        assert_eq!(s.bounds.max(), [2.0, 1.0]);
    }
}
