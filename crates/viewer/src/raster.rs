//! A software renderer for egui's output: its triangle meshes rasterised on the CPU, so that a
//! screenshot needs no GPU, no OpenGL or Vulkan driver and no display.
//!
//! It does what egui's GPU painters do (egui-wgpu's `fs_main_gamma_framebuffer`): each pixel
//! whose centre lies in a triangle (top-left fill rule, so that two triangles sharing an edge
//! never both cover a pixel on it) gets the vertex colours and texture coordinates
//! interpolated barycentrically, the texture sampled (bilinear or nearest, as the texture's
//! options say, clamped at the edges), colour times texel, blended premultiplied
//! (`src + dst (1 - src_alpha)`) in gamma space, inside the primitive's clip rectangle.
//! Anti-aliasing is egui's own (feathered edges in the meshes). Paint callbacks (custom GPU
//! code) are not drawn; the viewer has none.

use std::collections::HashMap;

use egui::epaint::{ClippedPrimitive, ImageDelta, Primitive, TextureId, Vertex};
use egui::{Color32, ImageData, TextureFilter, TexturesDelta};

/// A texture: premultiplied RGBA in 0..1, row-major.
#[derive(Debug, Clone)]
struct Texture {
    width: usize,
    height: usize,
    pixels: Vec<[f32; 4]>,
    linear: bool,
}

impl Texture {
    fn texel(&self, x: usize, y: usize) -> [f32; 4] {
        self.pixels
            .get(y * self.width + x)
            .copied()
            .unwrap_or([0.0; 4])
    }

    /// The texture at normalised coordinates `(u, v)`, clamped at the edges.
    fn sample(&self, u: f32, v: f32) -> [f32; 4] {
        let (w, h) = (self.width as f32, self.height as f32);
        if self.width == 0 || self.height == 0 {
            return [1.0; 4];
        }
        if !self.linear {
            let x = (u * w).floor().clamp(0.0, w - 1.0) as usize;
            let y = (v * h).floor().clamp(0.0, h - 1.0) as usize;
            return self.texel(x, y);
        }
        let x = (u * w - 0.5).clamp(0.0, w - 1.0);
        let y = (v * h - 0.5).clamp(0.0, h - 1.0);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as usize, y0 as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (a, b, c, d) = (
            self.texel(x0, y0),
            self.texel(x1, y0),
            self.texel(x0, y1),
            self.texel(x1, y1),
        );
        core::array::from_fn(|i| {
            let top = a[i] + (b[i] - a[i]) * fx;
            let bottom = c[i] + (d[i] - c[i]) * fx;
            top + (bottom - top) * fy
        })
    }
}

fn rgba(c: Color32) -> [f32; 4] {
    let [r, g, b, a] = c.to_array();
    [r, g, b, a].map(|v| f32::from(v) / 255.0)
}

/// An image rendered by [`SoftwareRenderer::paint`]: RGBA, 8 bits a channel, row-major,
/// opaque.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// `width * height * 4` bytes.
    pub rgba: Vec<u8>,
}

/// The textures egui has handed over, and the painting (see the module docs).
#[derive(Debug, Default)]
pub struct SoftwareRenderer {
    textures: HashMap<TextureId, Texture>,
}

impl SoftwareRenderer {
    /// A renderer with no textures.
    pub fn new() -> Self {
        Self::default()
    }

    /// Creates and updates the textures of a pass's `delta.set`; call before painting that
    /// pass's primitives, and [`SoftwareRenderer::free`] after.
    pub fn set_textures(&mut self, delta: &TexturesDelta) {
        for (id, deltas) in &delta.set {
            for image in deltas {
                self.set(*id, image);
            }
        }
    }

    /// Frees the textures of a pass's `delta.free`.
    pub fn free(&mut self, delta: &TexturesDelta) {
        for id in &delta.free {
            self.textures.remove(id);
        }
    }

    fn set(&mut self, id: TextureId, delta: &ImageDelta) {
        let ImageData::Color(image) = &delta.image;
        let [w, h] = image.size;
        let pixels: Vec<[f32; 4]> = image.pixels.iter().map(|c| rgba(*c)).collect();
        let linear = delta.options.magnification == TextureFilter::Linear;
        match delta.pos {
            None => {
                self.textures.insert(
                    id,
                    Texture {
                        width: w,
                        height: h,
                        pixels,
                        linear,
                    },
                );
            }
            Some([x0, y0]) => {
                let Some(texture) = self.textures.get_mut(&id) else {
                    return;
                };
                for (row, src) in pixels.chunks(w.max(1)).enumerate().take(h) {
                    let y = y0 + row;
                    if y >= texture.height || x0 >= texture.width {
                        continue;
                    }
                    let start = y * texture.width + x0;
                    let n = src.len().min(texture.width - x0);
                    if let (Some(dst), Some(src)) =
                        (texture.pixels.get_mut(start..start + n), src.get(..n))
                    {
                        dst.copy_from_slice(src);
                    }
                }
            }
        }
    }

    /// Paints `primitives` (tessellated at `pixels_per_point`) on a `width` x `height` image
    /// cleared to `clear`.
    pub fn paint(
        &self,
        primitives: &[ClippedPrimitive],
        width: u32,
        height: u32,
        pixels_per_point: f32,
        clear: Color32,
    ) -> Frame {
        let mut target = Target {
            width: width as usize,
            height: height as usize,
            pixels: vec![rgba(clear); width as usize * height as usize],
        };
        for primitive in primitives {
            let Primitive::Mesh(mesh) = &primitive.primitive else {
                continue;
            };
            let Some(texture) = self.textures.get(&mesh.texture_id) else {
                continue;
            };
            let clip = primitive.clip_rect;
            let to_px =
                |v: f32, max: usize| (v * pixels_per_point).round().clamp(0.0, max as f32) as usize;
            let clip = Clip {
                x0: to_px(clip.min.x, target.width),
                y0: to_px(clip.min.y, target.height),
                x1: to_px(clip.max.x, target.width),
                y1: to_px(clip.max.y, target.height),
            };
            if clip.x0 >= clip.x1 || clip.y0 >= clip.y1 {
                continue;
            }
            for tri in mesh.indices.chunks_exact(3) {
                let vertex = |i: u32| mesh.vertices.get(i as usize).copied();
                let (Some(a), Some(b), Some(c)) = (
                    tri.first().and_then(|&i| vertex(i)),
                    tri.get(1).and_then(|&i| vertex(i)),
                    tri.get(2).and_then(|&i| vertex(i)),
                ) else {
                    continue;
                };
                target.triangle([a, b, c], pixels_per_point, &clip, texture);
            }
        }
        let rgba = target
            .pixels
            .iter()
            .flat_map(|p| {
                // Premultiplied over an opaque clear colour: alpha is 1, the colour is final.
                [p[0], p[1], p[2], 1.0].map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            })
            .collect();
        Frame {
            width,
            height,
            rgba,
        }
    }
}

/// A clip rectangle in whole pixels, `[x0, x1) x [y0, y1)`.
#[derive(Debug, Clone, Copy)]
struct Clip {
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
}

/// The image being painted.
#[derive(Debug)]
struct Target {
    width: usize,
    height: usize,
    pixels: Vec<[f32; 4]>,
}

/// One edge's function `E(x, y) = a x + b y + c`, positive inside the triangle.
#[derive(Debug, Clone, Copy)]
struct Edge {
    a: f32,
    b: f32,
    c: f32,
    /// A pixel centre exactly on the edge belongs to the triangle (top-left rule).
    inclusive: bool,
}

impl Edge {
    /// The edge from `p` to `q` of a triangle wound so that its inside is on the left.
    fn new(p: [f32; 2], q: [f32; 2]) -> Self {
        let a = -(q[1] - p[1]);
        let b = q[0] - p[0];
        let c = -(a * p[0] + b * p[1]);
        Self {
            a,
            b,
            c,
            inclusive: a > 0.0 || (a == 0.0 && b > 0.0),
        }
    }

    fn at(&self, x: f32, y: f32) -> f32 {
        self.a * x + self.b * y + self.c
    }
}

impl Target {
    fn triangle(&mut self, v: [Vertex; 3], ppp: f32, clip: &Clip, texture: &Texture) {
        let mut p = v.map(|v| [v.pos.x * ppp, v.pos.y * ppp]);
        let mut v = v;
        let [p0, p1, p2] = p;
        let area = (p1[0] - p0[0]) * (p2[1] - p0[1]) - (p1[1] - p0[1]) * (p2[0] - p0[0]);
        if area == 0.0 || !area.is_finite() {
            return;
        }
        if area < 0.0 {
            p.swap(1, 2);
            v.swap(1, 2);
        }
        let area = area.abs();
        let [p0, p1, p2] = p;
        // Edge opposite each vertex: its function over the area is that vertex's weight.
        let edges = [Edge::new(p1, p2), Edge::new(p2, p0), Edge::new(p0, p1)];
        let min_y = p0[1].min(p1[1]).min(p2[1]);
        let max_y = p0[1].max(p1[1]).max(p2[1]);
        let min_x = p0[0].min(p1[0]).min(p2[0]);
        let max_x = p0[0].max(p1[0]).max(p2[0]);
        // Pixel rows and columns whose centres may lie inside.
        let first = |lo: f32, start: usize| ((lo - 0.5).ceil().max(start as f32)) as usize;
        let last = |hi: f32, end: usize| ((hi - 0.5).floor() + 1.0).clamp(0.0, end as f32) as usize;
        let (y_start, y_end) = (first(min_y, clip.y0), last(max_y, clip.y1));
        let (x_lo, x_hi) = (first(min_x, clip.x0), last(max_x, clip.x1));
        if y_start >= y_end || x_lo >= x_hi {
            return;
        }
        let colour = v.map(|v| rgba(v.color));
        let uv = v.map(|v| [v.uv.x, v.uv.y]);
        // Most of egui's area is flat colour on the white texel: one colour for the triangle.
        let flat =
            colour[0] == colour[1] && colour[1] == colour[2] && uv[0] == uv[1] && uv[1] == uv[2];
        let flat_colour = {
            let t = texture.sample(uv[0][0], uv[0][1]);
            core::array::from_fn::<f32, 4, _>(|i| colour[0][i] * t[i])
        };
        for y in y_start..y_end {
            let yc = y as f32 + 0.5;
            // The span of x where every edge function is inside, solved per edge.
            let mut lo = x_lo as f32 + 0.5;
            let mut hi = x_hi as f32 - 0.5;
            let mut empty = false;
            for e in &edges {
                let rest = e.b * yc + e.c;
                if e.a == 0.0 {
                    if rest < 0.0 || (rest == 0.0 && !e.inclusive) {
                        empty = true;
                    }
                } else {
                    let x = -rest / e.a;
                    if e.a > 0.0 {
                        lo = lo.max(x);
                    } else {
                        hi = hi.min(x);
                    }
                }
            }
            if empty || lo > hi {
                continue;
            }
            let px_start = ((lo - 0.5).ceil().max(x_lo as f32)) as usize;
            let px_end = ((hi - 0.5).floor() + 1.0).clamp(0.0, x_hi as f32) as usize;
            let row = y * self.width;
            for x in px_start..px_end {
                let xc = x as f32 + 0.5;
                let w = edges.map(|e| e.at(xc, yc));
                // The span was solved in floats; the exact test decides at its ends.
                let inside = w
                    .iter()
                    .zip(&edges)
                    .all(|(&w, e)| w > 0.0 || (w == 0.0 && e.inclusive));
                if !inside {
                    continue;
                }
                let src = if flat {
                    flat_colour
                } else {
                    let [w0, w1, w2] = w.map(|w| w / area);
                    let lerp = |a: f32, b: f32, c: f32| w0 * a + w1 * b + w2 * c;
                    let ([t0, t1, t2], [c0, c1, c2]) = (uv, colour);
                    let t = texture.sample(lerp(t0[0], t1[0], t2[0]), lerp(t0[1], t1[1], t2[1]));
                    core::array::from_fn(|ch| lerp(c0[ch], c1[ch], c2[ch]) * t[ch])
                };
                if let Some(dst) = self.pixels.get_mut(row + x) {
                    let keep = 1.0 - src[3];
                    *dst = core::array::from_fn(|ch| src[ch] + dst[ch] * keep);
                }
            }
        }
    }
}

/// What a frame asks of a software OpenGL renderer, counted from its meshes.
///
/// llvmpipe (Mesa's software OpenGL, the renderer of a machine without a GPU) shades pixels in
/// 4x4 blocks: every block a triangle touches is shaded whole, once per triangle. A frame's
/// painting time there follows `block_pixels` far more than the pixels actually covered: a long
/// one-pixel anti-aliased line touches a column or row of blocks with each of its thin
/// triangles. The count is deterministic, so a bench can track it where frame times are noisy.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FillEstimate {
    /// Triangles drawn.
    pub triangles: usize,
    /// Pixels covered, summed over triangles (overlaps counted each time).
    pub covered_pixels: f64,
    /// Pixels of the 4x4 blocks touched, summed over triangles (inside their clip rectangles).
    pub block_pixels: f64,
}

/// The [`FillEstimate`] of tessellated primitives at `pixels_per_point`.
pub fn fill_estimate(primitives: &[ClippedPrimitive], pixels_per_point: f32) -> FillEstimate {
    const BLOCK: f32 = 4.0;
    let mut out = FillEstimate::default();
    for p in primitives {
        let Primitive::Mesh(mesh) = &p.primitive else {
            continue;
        };
        let clip = p.clip_rect;
        let (cx0, cy0) = (clip.min.x * pixels_per_point, clip.min.y * pixels_per_point);
        let (cx1, cy1) = (clip.max.x * pixels_per_point, clip.max.y * pixels_per_point);
        for t in mesh.indices.chunks_exact(3) {
            let v: Vec<[f32; 2]> = t
                .iter()
                .filter_map(|i| mesh.vertices.get(*i as usize))
                .map(|v| [v.pos.x * pixels_per_point, v.pos.y * pixels_per_point])
                .collect();
            let [a, b, c] = v.as_slice() else {
                continue;
            };
            // A renderer drops a triangle with a vertex that is not a number.
            if !v.iter().flatten().all(|x| x.is_finite()) {
                continue;
            }
            out.triangles += 1;
            let cross = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
            out.covered_pixels += f64::from(cross.abs() / 2.0);
            // Wind the triangle counter-clockwise (inside on the left of each edge).
            let (b, c) = if cross >= 0.0 { (b, c) } else { (c, b) };
            let edges = [Edge::new(*a, *b), Edge::new(*b, *c), Edge::new(*c, *a)];
            let x0 = a[0].min(b[0]).min(c[0]).max(cx0);
            let x1 = a[0].max(b[0]).max(c[0]).min(cx1);
            let y0 = a[1].min(b[1]).min(c[1]).max(cy0);
            let y1 = a[1].max(b[1]).max(c[1]).min(cy1);
            if !(x0 < x1 && y0 < y1) {
                continue;
            }
            let (bx0, bx1) = ((x0 / BLOCK).floor() as i64, ((x1 / BLOCK).ceil() as i64));
            let (by0, by1) = ((y0 / BLOCK).floor() as i64, ((y1 / BLOCK).ceil() as i64));
            for by in by0..by1 {
                for bx in bx0..bx1 {
                    let (l, t) = (bx as f32 * BLOCK, by as f32 * BLOCK);
                    let corners = [
                        [l, t],
                        [l + BLOCK, t],
                        [l, t + BLOCK],
                        [l + BLOCK, t + BLOCK],
                    ];
                    // Touched unless all four corners are outside one edge.
                    let outside = edges
                        .iter()
                        .any(|e| corners.iter().all(|p| e.at(p[0], p[1]) < 0.0));
                    if !outside {
                        out.block_pixels += f64::from(BLOCK * BLOCK);
                    }
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use egui::epaint::{Mesh, WHITE_UV};
    use egui::{ColorImage, Rect, TextureOptions, pos2};

    /// A renderer with egui's default texture id as a 2x1 image: white at `WHITE_UV`'s side
    /// (left), red on the right.
    fn renderer(options: TextureOptions) -> SoftwareRenderer {
        let mut r = SoftwareRenderer::new();
        let mut delta = TexturesDelta::default();
        delta.push(
            TextureId::default(),
            ImageDelta::full(
                ColorImage::new([2, 1], vec![Color32::WHITE, Color32::RED]),
                options,
            ),
        );
        r.set_textures(&delta);
        delta.clear();
        r
    }

    fn mesh_rect(rect: Rect, colour: Color32) -> Mesh {
        let mut mesh = Mesh::default();
        mesh.add_colored_rect(rect, colour);
        for v in &mut mesh.vertices {
            v.uv = WHITE_UV;
        }
        mesh
    }

    fn clipped(mesh: Mesh, clip_rect: Rect) -> ClippedPrimitive {
        ClippedPrimitive {
            clip_rect,
            primitive: Primitive::Mesh(mesh),
        }
    }

    fn at(f: &Frame, x: u32, y: u32) -> [u8; 4] {
        let i = ((y * f.width + x) * 4) as usize;
        [f.rgba[i], f.rgba[i + 1], f.rgba[i + 2], f.rgba[i + 3]]
    }

    /// Half-transparent grey: a pixel covered twice would come out brighter.
    const HALF: Color32 = Color32::from_rgba_premultiplied(128, 128, 128, 128);

    #[test]
    fn a_rectangle_covers_exactly_its_pixels_once() {
        let r = renderer(TextureOptions::NEAREST);
        let rect = Rect::from_min_max(pos2(2.0, 3.0), pos2(7.0, 9.0));
        let f = r.paint(
            &[clipped(mesh_rect(rect, HALF), Rect::EVERYTHING)],
            10,
            12,
            1.0,
            Color32::BLACK,
        );
        for y in 0..12 {
            for x in 0..10 {
                let inside = (2..7).contains(&x) && (3..9).contains(&y);
                let expected = if inside {
                    [128, 128, 128, 255]
                } else {
                    [0, 0, 0, 255]
                };
                assert_eq!(at(&f, x, y), expected, "({x}, {y})");
            }
        }
    }

    /// Triangles sharing edges through pixel centres (a fan around a centre at a pixel
    /// centre): every pixel is blended exactly once, the top-left rule at work.
    #[test]
    fn shared_edges_through_pixel_centres_blend_once() {
        let r = renderer(TextureOptions::NEAREST);
        let mut mesh = Mesh::default();
        let centre = pos2(8.5, 8.5);
        let corners = [
            pos2(0.5, 0.5),
            pos2(16.5, 0.5),
            pos2(16.5, 16.5),
            pos2(0.5, 16.5),
        ];
        mesh.colored_vertex(centre, HALF);
        for c in corners {
            mesh.colored_vertex(c, HALF);
        }
        for v in &mut mesh.vertices {
            v.uv = WHITE_UV;
        }
        for k in 0..4u32 {
            mesh.add_triangle(0, 1 + k, 1 + (k + 1) % 4);
        }
        let f = r.paint(
            &[clipped(mesh, Rect::EVERYTHING)],
            18,
            18,
            1.0,
            Color32::BLACK,
        );
        for y in 0..18 {
            for x in 0..18 {
                // Pixel centres in [0.5, 16.5) on both axes: pixels 0..16.
                let inside = x < 16 && y < 16;
                let expected = if inside {
                    [128, 128, 128, 255]
                } else {
                    [0, 0, 0, 255]
                };
                assert_eq!(at(&f, x, y), expected, "({x}, {y})");
            }
        }
    }

    #[test]
    fn the_clip_rectangle_and_pixels_per_point_are_honoured() {
        let r = renderer(TextureOptions::NEAREST);
        let rect = Rect::from_min_max(pos2(0.0, 0.0), pos2(10.0, 10.0));
        let clip = Rect::from_min_max(pos2(1.0, 2.0), pos2(3.0, 4.0));
        // Two pixels a point: the clip is pixels 2..6 x 4..8.
        let f = r.paint(
            &[clipped(mesh_rect(rect, Color32::WHITE), clip)],
            12,
            12,
            2.0,
            Color32::BLACK,
        );
        for y in 0..12 {
            for x in 0..12 {
                let inside = (2..6).contains(&x) && (4..8).contains(&y);
                let expected = if inside { [255; 4] } else { [0, 0, 0, 255] };
                assert_eq!(at(&f, x, y), expected, "({x}, {y})");
            }
        }
    }

    /// Texture coordinates interpolated and sampled: nearest gives the texel, linear blends the
    /// two texels halfway between their centres.
    #[test]
    fn textures_are_sampled_nearest_or_linear() {
        let mut mesh = Mesh::default();
        let rect = Rect::from_min_max(pos2(0.0, 0.0), pos2(8.0, 1.0));
        mesh.add_rect_with_uv(
            rect,
            Rect::from_min_max(pos2(0.0, 0.0), pos2(1.0, 1.0)),
            Color32::WHITE,
        );
        let nearest = renderer(TextureOptions::NEAREST).paint(
            &[clipped(mesh.clone(), Rect::EVERYTHING)],
            8,
            1,
            1.0,
            Color32::BLACK,
        );
        assert_eq!(at(&nearest, 1, 0), [255, 255, 255, 255]);
        assert_eq!(at(&nearest, 6, 0), [255, 0, 0, 255]);
        let linear = renderer(TextureOptions::LINEAR).paint(
            &[clipped(mesh, Rect::EVERYTHING)],
            8,
            1,
            1.0,
            Color32::BLACK,
        );
        // Pixel 0 (u = 1/16) clamps to the white texel; pixels 3 and 4 straddle the middle.
        assert_eq!(at(&linear, 0, 0), [255, 255, 255, 255]);
        let [r3, g3, _, _] = at(&linear, 3, 0);
        let [r4, g4, _, _] = at(&linear, 4, 0);
        assert_eq!((r3, r4), (255, 255));
        assert!(g3 > 128 && g4 < 128 && g3 < 255 && g4 > 0, "{g3} {g4}");
    }

    #[test]
    fn partial_updates_and_frees_apply() {
        let mut r = renderer(TextureOptions::NEAREST);
        let mut delta = TexturesDelta::default();
        delta.push(
            TextureId::default(),
            ImageDelta::partial(
                [1, 0],
                ColorImage::new([1, 1], vec![Color32::BLUE]),
                TextureOptions::NEAREST,
            ),
        );
        r.set_textures(&delta);
        delta.clear();
        let mut mesh = Mesh::default();
        mesh.add_rect_with_uv(
            Rect::from_min_max(pos2(0.0, 0.0), pos2(2.0, 1.0)),
            Rect::from_min_max(pos2(0.0, 0.0), pos2(1.0, 1.0)),
            Color32::WHITE,
        );
        let f = r.paint(
            &[clipped(mesh.clone(), Rect::EVERYTHING)],
            2,
            1,
            1.0,
            Color32::BLACK,
        );
        assert_eq!((at(&f, 0, 0), at(&f, 1, 0)), ([255; 4], [0, 0, 255, 255]));
        delta.free.insert(TextureId::default());
        r.free(&delta);
        delta.clear();
        // A mesh on a texture that does not exist is not drawn.
        let f = r.paint(
            &[clipped(mesh, Rect::EVERYTHING)],
            2,
            1,
            1.0,
            Color32::BLACK,
        );
        assert_eq!(f.rgba, vec![0, 0, 0, 255, 0, 0, 0, 255]);
    }

    #[test]
    fn fill_estimate_counts_the_blocks_a_thin_bar_touches() {
        // A one-pixel bar 40 pixels long: 40 pixels covered, ten 4x4 blocks for each of its
        // two triangles.
        let bar = mesh_rect(
            Rect::from_min_max(pos2(0.0, 0.0), pos2(40.0, 1.0)),
            Color32::WHITE,
        );
        let clip = Rect::from_min_max(pos2(0.0, 0.0), pos2(100.0, 100.0));
        let primitives = [ClippedPrimitive {
            clip_rect: clip,
            primitive: Primitive::Mesh(bar),
        }];
        let e = fill_estimate(&primitives, 1.0);
        assert_eq!(e.triangles, 2);
        assert!((e.covered_pixels - 40.0).abs() < 1e-9, "{e:?}");
        assert!((e.block_pixels - 2.0 * 10.0 * 16.0).abs() < 1e-9, "{e:?}");
        // Clipped to its first 20 pixels: half the blocks.
        let primitives = [ClippedPrimitive {
            clip_rect: Rect::from_min_max(pos2(0.0, 0.0), pos2(20.0, 100.0)),
            primitive: primitives[0].primitive.clone(),
        }];
        assert!((fill_estimate(&primitives, 1.0).block_pixels - 2.0 * 5.0 * 16.0).abs() < 1e-9);
        // A triangle with a vertex that is not a number is dropped, as a renderer drops it.
        let mut bad = mesh_rect(
            Rect::from_min_max(pos2(0.0, 0.0), pos2(40.0, 1.0)),
            Color32::WHITE,
        );
        bad.vertices[0].pos.x = f32::NAN;
        let primitives = [ClippedPrimitive {
            clip_rect: clip,
            primitive: Primitive::Mesh(bad),
        }];
        let e = fill_estimate(&primitives, 1.0);
        assert_eq!(e.triangles, 1, "{e:?}");
        assert!(
            e.covered_pixels.is_finite() && e.block_pixels <= 10.0 * 16.0,
            "{e:?}"
        );
    }
}
