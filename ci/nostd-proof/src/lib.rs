//! Links the firmware crates into a `#![no_std]` static library (see Cargo.toml).
#![no_std]

use fpga_link::{Decoder, Event, Header, MAX_PACKET_LEN, encode_packet};
use harris_core::{Feature, HarrisStream, Registers};

/// Width of the test image: the detector's line buffers are sized for it at compile time.
const WIDTH: usize = 32;

/// Runs the board detector on a synthetic 32x32 image with one bright 4x4 lamp and returns the
/// number of features (1), or -1 on a configuration error. No heap, no std.
#[unsafe(no_mangle)]
pub extern "C" fn stereonav_nostd_harris_features() -> i32 {
    let regs = Registers { width: WIDTH, height: WIDTH, ..Registers::default() };
    let Ok(mut stream) = HarrisStream::<WIDTH>::new(regs) else {
        return -1;
    };
    let mut count = 0;
    for y in 0..WIDTH {
        let mut row = [0u8; WIDTH];
        if (14..18).contains(&y) {
            row[14..18].fill(255);
        }
        match stream.push_row(&row) {
            Ok(features) => count += features.len(),
            Err(_) => return -1,
        }
    }
    i32::try_from(count).unwrap_or(-1)
}

/// Encodes a packet with two features and decodes it back a byte at a time, as firmware that
/// relays the board's stream would; returns the number of features decoded (2), or -1.
#[unsafe(no_mangle)]
pub extern "C" fn stereonav_nostd_stream_round_trip() -> i32 {
    let left = [Feature { x_q4: 160, y_q4: 320, r: 1 << 20 }];
    let right = [Feature { x_q4: 150, y_q4: 320, r: 1 << 19 }];
    let mut packet = [0u8; MAX_PACKET_LEN];
    let Ok(n) = encode_packet(&Header { frame: 1, ..Header::default() }, &left, &right, &mut packet)
    else {
        return -1;
    };
    let mut decoder = Decoder::new();
    let mut features = 0;
    for byte in packet.iter().take(n) {
        let mut rest = core::slice::from_ref(byte);
        loop {
            let (used, event) = decoder.decode(rest);
            rest = rest.get(used..).unwrap_or_default();
            match event {
                Some(Event::Frame(frame)) => features += frame.left().len() + frame.right().len(),
                Some(Event::Corrupt(_)) => return -1,
                None => break,
            }
        }
    }
    i32::try_from(features).unwrap_or(-1)
}

#[panic_handler]
fn panic(_info: &core::panic::PanicInfo<'_>) -> ! {
    loop {}
}
