//! Decoding speed on a realistic stream: about 500 features per camera per packet, cut into
//! random chunks (1 byte to 64 KiB), every feature read by the consumer.
//!
//! `cargo bench -p fpga-link --bench decode`

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use fpga_link::{Decoder, Encoder, Event, Feature};

/// xorshift64*, so the stream is the same on every run.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
}

fn features(rng: &mut Rng, n: usize) -> Vec<Feature> {
    let mut f: Vec<Feature> = (0..n)
        .map(|_| {
            let v = rng.next();
            Feature {
                x_q4: (v % (748 * 16)) as u16,
                y_q4: ((v >> 16) % (476 * 16)) as u16,
                r: (1 << 18) + ((v >> 32) % (1 << 26)) as i32,
            }
        })
        .collect();
    f.sort_by_key(|f| (f.y_q4, f.x_q4));
    f
}

fn realistic_stream() -> (Vec<u8>, Vec<std::ops::Range<usize>>) {
    let mut rng = Rng(0x5EED);
    let mut enc = Encoder::default();
    let mut bytes = Vec::new();
    for i in 0..256u64 {
        let n_left = 480 + (rng.next() % 41) as usize;
        let n_right = 480 + (rng.next() % 41) as usize;
        let (left, right) = (features(&mut rng, n_left), features(&mut rng, n_right));
        enc.encode_to_vec(50_000 * i, (&left, false), (&right, false), &mut bytes)
            .unwrap_or_else(|e| panic!("{e}"));
    }
    let mut chunks = Vec::new();
    let mut at = 0;
    while at < bytes.len() {
        // Log-uniform chunk sizes from 1 byte to 64 KiB.
        let size = 1usize << (rng.next() % 17);
        let end = (at + size + (rng.next() as usize % size.max(1))).min(bytes.len());
        chunks.push(at..end);
        at = end;
    }
    (bytes, chunks)
}

fn bench(c: &mut Criterion) {
    let (bytes, chunks) = realistic_stream();
    let mut group = c.benchmark_group("fpga_link");
    group.throughput(Throughput::Bytes(bytes.len() as u64));
    group.bench_function("decode_500_features_per_camera_random_chunks", |b| {
        b.iter(|| {
            let mut decoder = Decoder::new();
            let mut checksum = 0i64;
            for range in &chunks {
                let mut rest = &bytes[range.clone()];
                loop {
                    let (used, event) = decoder.decode(black_box(rest));
                    rest = &rest[used..];
                    match event {
                        Some(Event::Frame(frame)) => {
                            for f in frame.left().chain(frame.right()) {
                                checksum += i64::from(f.r) + i64::from(f.x_q4) + i64::from(f.y_q4);
                            }
                        }
                        Some(Event::Corrupt(_)) => checksum -= 1,
                        None => break,
                    }
                }
            }
            (checksum, decoder.stats())
        });
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
