//! Left and right images paired by stamp (vehicle-interfaces.md 4.1): a stereo frame is a
//! left and a right image whose stamps differ by at most a quarter of the frame interval.
//!
//! The frame interval is the median of the last [`INTERVAL_WINDOW`] steps between left stamps
//! (the right's when the left has too few), so a camera that drops a frame or changes its rate
//! does not throw the pairing off. Images are held, sorted by stamp, until the pairing of the
//! oldest left is certain: a right image later than the left's window has been seen (images
//! come roughly in stamp order), or the log ends, or the images held pass [`MAX_HELD`] or
//! [`MAX_HELD_BYTES`]. The limits are far above what a recorder's interleaving needs (a few
//! images), so that a bag written topic by topic (every left image, then every right one: a
//! valid MCAP file, as folder-to-bag scripts write it) still pairs as long as one camera's
//! images fit; past them the oldest left is decided with what has come, and the decisions so
//! forced are counted ([`Pairer::forced`]). A left pairs with the right nearest in stamp within
//! the window; an image left without a partner is a frame with one image, counted.

use std::collections::VecDeque;

use vehicle_log::CameraImage;

/// Steps between stamps over which the frame interval is the median.
pub const INTERVAL_WINDOW: usize = 15;
/// Most images held (both sides) waiting for their partners.
pub const MAX_HELD: usize = 8192;
/// Most bytes of image payload held (both sides): 700 raw 752x480 images, 3700 JPEG ones.
pub const MAX_HELD_BYTES: usize = 256 << 20;

/// An image's payload bytes.
fn payload_len(image: &CameraImage) -> usize {
    match &image.payload {
        vehicle_log::ImagePayload::Raw { data, .. }
        | vehicle_log::ImagePayload::Compressed { data, .. } => data.len(),
    }
}

/// What the pairer gives, in stamp order.
#[derive(Debug)]
pub enum Paired {
    /// A stereo frame.
    Frame {
        /// The left image.
        left: CameraImage,
        /// The right image.
        right: CameraImage,
    },
    /// An image without a partner.
    Alone(CameraImage),
}

/// Pairs left and right images by stamp (see the module docs).
#[derive(Debug, Default)]
pub struct Pairer {
    left: VecDeque<CameraImage>,
    right: VecDeque<CameraImage>,
    /// The last stamps of each side, in arrival order, for the interval.
    left_stamps: VecDeque<u64>,
    right_stamps: VecDeque<u64>,
    /// The latest stamp seen on each side.
    left_latest: Option<u64>,
    right_latest: Option<u64>,
    ended: bool,
    /// Payload bytes held.
    held_bytes: usize,
    /// Decisions forced by the limits.
    forced: u64,
}

fn push_stamp(stamps: &mut VecDeque<u64>, t: u64) {
    stamps.push_back(t);
    if stamps.len() > INTERVAL_WINDOW + 1 {
        stamps.pop_front();
    }
}

/// The median positive step between the sorted stamps.
fn median_step(stamps: &VecDeque<u64>) -> Option<u64> {
    let mut sorted: Vec<u64> = stamps.iter().copied().collect();
    sorted.sort_unstable();
    let mut steps: Vec<u64> = sorted
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|&d| d > 0)
        .collect();
    if steps.is_empty() {
        return None;
    }
    steps.sort_unstable();
    Some(steps[steps.len() / 2])
}

fn insert_sorted(queue: &mut VecDeque<CameraImage>, image: CameraImage) {
    // Images come in stamp order but for a few: search from the back.
    let at = queue
        .iter()
        .rposition(|i| i.t_us <= image.t_us)
        .map_or(0, |p| p + 1);
    queue.insert(at, image);
}

impl Pairer {
    /// An empty pairer.
    pub fn new() -> Self {
        Self::default()
    }

    /// The frame interval so far, us (`None` until a side has two stamps).
    pub fn interval_us(&self) -> Option<u64> {
        median_step(&self.left_stamps).or_else(|| median_step(&self.right_stamps))
    }

    /// The largest stamp difference of a pair, us.
    pub fn tolerance_us(&self) -> Option<u64> {
        self.interval_us().map(|i| i / 4)
    }

    /// Images held.
    pub fn held(&self) -> usize {
        self.left.len() + self.right.len()
    }

    /// Pairing decisions forced by [`MAX_HELD`] or [`MAX_HELD_BYTES`] before they were
    /// certain (a bag far from stamp order).
    pub fn forced(&self) -> u64 {
        self.forced
    }

    /// Takes a left image.
    pub fn push_left(&mut self, image: CameraImage) {
        self.held_bytes += payload_len(&image);
        push_stamp(&mut self.left_stamps, image.t_us);
        self.left_latest = Some(self.left_latest.map_or(image.t_us, |t| t.max(image.t_us)));
        insert_sorted(&mut self.left, image);
    }

    /// Takes a right image.
    pub fn push_right(&mut self, image: CameraImage) {
        self.held_bytes += payload_len(&image);
        push_stamp(&mut self.right_stamps, image.t_us);
        self.right_latest = Some(self.right_latest.map_or(image.t_us, |t| t.max(image.t_us)));
        insert_sorted(&mut self.right, image);
    }

    /// No more images: what is held is let out.
    pub fn end(&mut self) {
        self.ended = true;
    }

    /// The next frame or lone image whose pairing is certain, in stamp order.
    pub fn pop(&mut self) -> Option<Paired> {
        let out = self.decide();
        if let Some(p) = &out {
            let n = match p {
                Paired::Frame { left, right } => payload_len(left) + payload_len(right),
                Paired::Alone(i) => payload_len(i),
            };
            self.held_bytes = self.held_bytes.saturating_sub(n);
        }
        out
    }

    fn decide(&mut self) -> Option<Paired> {
        let over = self.held() > MAX_HELD || self.held_bytes > MAX_HELD_BYTES;
        let forced = self.ended || over;
        // Until an interval is known (two stamps on a side) only identical stamps pair.
        let tol = self.tolerance_us();
        if tol.is_none() && !forced {
            return None;
        }
        let tol = tol.unwrap_or(0);
        let Some(left_t) = self.left.front().map(|l| l.t_us) else {
            // No left waiting: a right is alone once a later left could no longer pair
            // with it, or when forced.
            let right_t = self.right.front()?.t_us;
            let past = self.left_latest.is_some_and(|t| t > right_t + tol);
            if !(forced || past) {
                return None;
            }
            return self.right.pop_front().map(Paired::Alone);
        };
        // A right older than the left's window is alone.
        if self.right.front().is_some_and(|r| r.t_us + tol < left_t) {
            return self.right.pop_front().map(Paired::Alone);
        }
        // The left's partner is certain once a right past its window has been seen.
        let sure = self.ended || self.right_latest.is_some_and(|t| t > left_t + tol);
        if !sure && !over {
            return None;
        }
        if !sure {
            self.forced += 1;
        }
        let best = self
            .right
            .iter()
            .enumerate()
            .take_while(|(_, r)| r.t_us <= left_t + tol)
            .min_by_key(|(_, r)| r.t_us.abs_diff(left_t))
            .map(|(i, _)| i);
        let left = self.left.pop_front()?;
        match best {
            Some(i) => {
                // Rights before the partner are older than it: alone, let out next (they
                // are within the window but a closer one won).
                let right = self.right.remove(i)?;
                Some(Paired::Frame { left, right })
            }
            None => Some(Paired::Alone(left)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vehicle_log::{ImagePayload, Side};

    fn image(side: Side, t_us: u64) -> CameraImage {
        CameraImage {
            side,
            t_us,
            log_time_ns: t_us * 1000,
            payload: ImagePayload::Compressed {
                format: String::new(),
                data: Vec::new(),
            },
        }
    }

    fn run(lefts: &[u64], rights: &[u64]) -> Vec<String> {
        let mut p = Pairer::new();
        let mut out = Vec::new();
        let drain = |p: &mut Pairer, out: &mut Vec<String>| {
            while let Some(x) = p.pop() {
                out.push(match x {
                    Paired::Frame { left, right } => format!("{}+{}", left.t_us, right.t_us),
                    Paired::Alone(i) => format!("{:?}{}", i.side, i.t_us),
                });
            }
        };
        // Interleaved in stamp order, as a recorder writes them.
        let mut all: Vec<(u64, Side)> = lefts
            .iter()
            .map(|&t| (t, Side::Left))
            .chain(rights.iter().map(|&t| (t, Side::Right)))
            .collect();
        all.sort_by_key(|x| x.0);
        for (t, side) in all {
            match side {
                Side::Left => p.push_left(image(side, t)),
                Side::Right => p.push_right(image(side, t)),
            }
            drain(&mut p, &mut out);
        }
        p.end();
        drain(&mut p, &mut out);
        out
    }

    #[test]
    fn synchronised_cameras_pair() {
        let t: Vec<u64> = (0..5).map(|k| 1000 + 50_000 * k).collect();
        assert_eq!(
            run(&t, &t),
            [
                "1000+1000",
                "51000+51000",
                "101000+101000",
                "151000+151000",
                "201000+201000"
            ]
        );
    }

    #[test]
    fn quarter_interval_is_the_limit() {
        // Interval 50 ms: 12.5 ms pairs, 12.6 ms does not.
        let l: Vec<u64> = (0..6).map(|k| 50_000 * k).collect();
        let r = [
            12_500,
            50_000 + 12_600,
            100_000,
            150_000 - 3000,
            200_000,
            250_000,
        ];
        assert_eq!(
            run(&l, &r),
            [
                "0+12500",
                "Left50000",
                "Right62600",
                "100000+100000",
                "150000+147000",
                "200000+200000",
                "250000+250000"
            ]
        );
    }

    #[test]
    fn dropped_images_leave_the_other_alone() {
        let l = [0, 50_000, 100_000, 150_000, 200_000];
        let r = [0, 100_000, 200_000];
        assert_eq!(
            run(&l, &r),
            [
                "0+0",
                "Left50000",
                "100000+100000",
                "Left150000",
                "200000+200000"
            ]
        );
        assert_eq!(run(&[], &[0, 50_000]), ["Right0", "Right50000"]);
        let lefts: Vec<u64> = (0..40).map(|k| 50_000 * k).collect();
        assert_eq!(run(&lefts, &[]).len(), 40);
    }

    #[test]
    fn topic_by_topic_bag_pairs_every_frame() {
        // Every left image first, then every right one.
        let mut p = Pairer::new();
        let mut out = Vec::new();
        for k in 0..100 {
            p.push_left(image(Side::Left, 50_000 * k));
            out.extend(std::iter::from_fn(|| p.pop()));
        }
        for k in 0..100 {
            p.push_right(image(Side::Right, 50_000 * k + 1000));
            out.extend(std::iter::from_fn(|| p.pop()));
        }
        p.end();
        out.extend(std::iter::from_fn(|| p.pop()));
        let frames = out
            .iter()
            .filter(|x| matches!(x, Paired::Frame { .. }))
            .count();
        assert_eq!((frames, out.len(), p.forced()), (100, 100, 0));
    }
}
