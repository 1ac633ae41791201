//! Rectification of raw board features (vehicle-interfaces.md 1.1): the cost per feature of
//! `Lens::rectify_point` (the exact inverse and the rotation, what the navigator runs per
//! feature) for EuRoC's
//! radtan lens and a fisheye, over a grid covering the whole 752 x 480 image. Target: at most
//! 100 ns a feature.
//!
//! `cargo bench -p calib --bench lens`

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::{Matrix3, Rotation3, Vector2};
use rig_model::lens::{Lens, LensModel};

fn lenses() -> [(&'static str, Lens); 2] {
    let rot = Rotation3::from_euler_angles(0.004, -0.012, 0.001).into_inner();
    [
        (
            "radtan",
            Lens {
                model: LensModel::PlumbBob {
                    k1: -0.283_408_11,
                    k2: 0.073_959_07,
                    p1: 0.000_193_59,
                    p2: 1.761_871_14e-5,
                    k3: 0.0,
                },
                fx: 458.654,
                fy: 457.296,
                cx: 367.215,
                cy: 248.375,
                rectification: rot,
            },
        ),
        (
            "fisheye",
            Lens {
                model: LensModel::Equidistant {
                    k1: -0.0137,
                    k2: 0.0182,
                    k3: -0.0114,
                    k4: 0.0025,
                },
                fx: 360.0,
                fy: 360.4,
                cx: 375.0,
                cy: 240.5,
                rectification: Matrix3::identity(),
            },
        ),
    ]
}

fn bench(c: &mut Criterion) {
    let points: Vec<Vector2<f64>> = (0..480)
        .step_by(8)
        .flat_map(|v| {
            (0..752)
                .step_by(8)
                .map(move |u| Vector2::new(f64::from(u), f64::from(v)))
        })
        .collect();
    let mut group = c.benchmark_group("rectify");
    group.throughput(Throughput::Elements(points.len() as u64));
    for (name, lens) in lenses() {
        group.bench_function(name, |b| {
            b.iter(|| {
                let mut acc = 0.0;
                for p in &points {
                    if let Some(q) = lens.rectify_point(black_box(*p), 436.2443, 364.4412, 256.9517)
                    {
                        acc += q.x;
                    }
                }
                acc
            });
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
