//! Monte Carlo of bit errors: `COPIES` copies of a log, each with 1 to 10 bits flipped at
//! random (seeded), read by the damage-tolerant reader (`vehicle_log::LogReader`) and by the
//! `mcap` crate's linear reader as the reader before it used it (stop at the first error,
//! refuse a file without the magic); for each, the share of the `/fpga/features` and `/odom`
//! messages read, against the share lying in chunks whose bytes no flip touched.
//!
//! ```sh
//! cargo run --release -p vehicle-log --example damage_mc -- fixtures/logs/paper-experiment-pymcap.mcap 30 1
//! ```
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stdout)]

#[path = "../tests/integration/common/layout.rs"]
mod layout;

use std::io::Cursor;

use layout::{Damage, Layout};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use vehicle_log::{LogReader, Record};

/// xorshift64*, as the tests' generator.
struct Rng(u64);

impl Rng {
    fn below(&mut self, n: u64) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) % n.max(1)
    }
}

/// `/fpga/features` and `/odom` messages the damage-tolerant reader yields.
/// An error (there should be none) is printed and counts as nothing read.
fn read_new(bytes: &[u8]) -> u64 {
    let reader = match LogReader::new(Cursor::new(bytes), "copy.mcap") {
        Ok(reader) => reader,
        Err(err) => {
            println!("error: {err}");
            return 0;
        }
    };
    let mut n = 0;
    for record in reader {
        match record {
            Ok(Record::Features { .. } | Record::Odom(_)) => n += 1,
            Ok(_) => {}
            Err(err) => {
                println!("error: {err}");
                break;
            }
        }
    }
    n
}

/// The same messages as the reader before this one read them: the `mcap` crate's linear
/// reader with CRC checks, stopping at the first error; nothing without the magic.
fn read_old(bytes: &[u8]) -> u64 {
    if bytes.get(..8) != Some(mcap::MAGIC) {
        return 0;
    }
    let options = LinearReaderOptions::default()
        .with_prevalidate_chunk_crcs(true)
        .with_validate_data_section_crc(true)
        .with_validate_summary_section_crc(true)
        .with_record_length_limit(vehicle_log::MAX_RECORD_LEN);
    let mut reader = LinearReader::new_with_options(options);
    let mut rest = bytes;
    let mut channels = std::collections::HashMap::new();
    let mut n = 0;
    while let Some(event) = reader.next_event() {
        match event {
            Err(_) => break,
            Ok(LinearReadEvent::ReadRequest(need)) => {
                let take = need.max(1 << 16).min(rest.len());
                let buf = reader.insert(take);
                buf.copy_from_slice(&rest[..take]);
                reader.notify_read(take);
                rest = &rest[take..];
            }
            Ok(LinearReadEvent::Record { opcode, data }) => {
                match mcap::parse_record(opcode, data) {
                    Ok(mcap::records::Record::Channel(c)) => {
                        channels.insert(c.id, c.topic);
                    }
                    Ok(mcap::records::Record::Message { header, .. }) => {
                        if let Some(topic) = channels.get(&header.channel_id)
                            && (topic == "/fpga/features" || topic == "/odom")
                        {
                            n += 1;
                        }
                    }
                    Ok(mcap::records::Record::DataEnd(_)) => break,
                    Ok(_) => {}
                    Err(_) => break,
                }
            }
        }
    }
    n
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args
        .get(1)
        .map_or("fixtures/logs/paper-experiment-pymcap.mcap", String::as_str);
    let copies: usize = args.get(2).map_or(30, |a| a.parse().unwrap());
    let seed: u64 = args.get(3).map_or(1, |a| a.parse().unwrap());
    let bytes = std::fs::read(path).unwrap();
    let layout = Layout::of(&bytes);
    let ours = |c: &u16| matches!(layout.topics[c].as_str(), "/fpga/features" | "/odom");
    let total = layout.messages().filter(|k| ours(&k.channel_id)).count() as f64;
    println!(
        "{path}: {} bytes, {} chunks, {total} /fpga/features + /odom messages; {copies} copies, \
         1-10 flipped bits each, seed {seed}",
        bytes.len(),
        layout.chunks.len()
    );
    println!("copy flips  spared%  read%  old-reader%");
    let mut rng = Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
    let (mut spared_v, mut read_v, mut old_v) = (Vec::new(), Vec::new(), Vec::new());
    let mut below_spared = 0;
    for copy in 0..copies {
        let n = 1 + rng.below(10);
        let damage = Damage {
            flips: (0..n)
                .map(|_| (rng.below(bytes.len() as u64), rng.below(8) as u8))
                .collect(),
            cut: None,
        };
        let damaged = damage.apply(&bytes);
        let spared = layout
            .spared(|r| damage.touches(r))
            .filter(|k| ours(&k.channel_id))
            .count() as f64;
        let read = read_new(&damaged) as f64;
        let old = read_old(&damaged) as f64;
        if read < spared {
            below_spared += 1;
            println!("fewer than spared: flips {:?}", damage.flips);
        }
        println!(
            "{copy:4} {n:5}  {:7.1}  {:5.1}  {:11.1}",
            100.0 * spared / total,
            100.0 * read / total,
            100.0 * old / total
        );
        spared_v.push(100.0 * spared / total);
        read_v.push(100.0 * read / total);
        old_v.push(100.0 * old / total);
    }
    let worst = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
    println!(
        "median: spared {:.1} %, read {:.1} %, old reader {:.1} %",
        median(&mut spared_v.clone()),
        median(&mut read_v.clone()),
        median(&mut old_v.clone())
    );
    println!(
        "worst:  spared {:.1} %, read {:.1} %, old reader {:.1} %",
        worst(&spared_v),
        worst(&read_v),
        worst(&old_v)
    );
    println!("copies where fewer were read than the spared chunks hold: {below_spared}");
}
