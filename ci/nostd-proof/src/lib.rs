//! Links the firmware crates into a `#![no_std]` static library (see Cargo.toml).
#![no_std]

use harris_core::{HarrisStream, Registers};

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

#[panic_handler]
fn panic(_info: &core::panic::PanicInfo<'_>) -> ! {
    loop {}
}
