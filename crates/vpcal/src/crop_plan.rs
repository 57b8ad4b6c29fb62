//! Which vehicle boxes of consecutive frames go through the VP network.
//!
//! A fixed camera sees each vehicle in tens of frames, and the network sees the same car the
//! same way in each of them: its fiftieth crop adds little that its first few did not. The
//! planner follows the boxes from frame to frame (greedy IoU matching, as the box tracker
//! does, bridging short gaps) and sends a vehicle's box to the network when
//!
//! - it is the vehicle's first box;
//! - it is at least [`CropPlanSettings::grow`] times the area of the largest box of the
//!   vehicle sent so far (an approaching vehicle: its later, larger crops show more);
//! - the vehicle has been seen twice as many times as when its last crop was sent (crops
//!   spread over the track, fewer as it goes on: boxes 1, 2, 4, 8, 16, ...);
//!
//! the spread-out crops at most [`CropPlanSettings::max_crops`] times per vehicle (the
//! growing ones are bounded by the frame: `log(frame area / smallest box) / log(grow)`). A
//! vehicle seen in `n` frames gets about `log2(n)` crops plus those of its growth.
//!
//! Every box still makes a record: the tracks, the speeds and the aggregation's vehicle
//! links use them all, and the edgelets are cut in every box (they are cheap, and each
//! frame's edges differ: on low-resolution clips most of the roll and VP1 evidence). A box
//! not sent carries its vehicle's latest network VPs, marked as copied: they gate its
//! edgelets, and the fits of the network's rays leave it out.

use vpcal_geom::BoxPx;

/// Settings of [`CropPlanner`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CropPlanSettings {
    /// At most this many crops of one vehicle for spreading over its track (crops of a
    /// growing box are not counted against it).
    pub max_crops: u32,
    /// A box this many times the area of the vehicle's largest crop so far is sent again.
    pub grow: f64,
    /// Boxes of successive frames overlapping at least this much are one vehicle.
    pub match_iou: f64,
    /// A vehicle not seen for more than this many source frames is gone.
    pub max_gap_frames: u64,
}

impl CropPlanSettings {
    /// The settings for footage processed at every `step`-th frame: the gap the box tracker
    /// bridges (8 processed frames) in source frames.
    pub fn for_step(step: u64) -> CropPlanSettings {
        CropPlanSettings {
            max_crops: 10,
            grow: 1.5,
            match_iou: 0.3,
            max_gap_frames: 8 * step.max(1),
        }
    }
}

#[derive(Debug, Clone)]
struct Followed {
    id: u64,
    last: BoxPx,
    last_frame: u64,
    seen: u32,
    seen_at_crop: u32,
    crops: u32,
    largest_crop_area: f64,
}

/// Follows the boxes of consecutive frames and says which go through the network.
#[derive(Debug, Clone)]
pub struct CropPlanner {
    settings: CropPlanSettings,
    followed: Vec<Followed>,
    next_id: u64,
}

impl CropPlanner {
    pub fn new(settings: CropPlanSettings) -> CropPlanner {
        CropPlanner {
            settings,
            followed: Vec::new(),
            next_id: 0,
        }
    }

    /// For each of `boxes` (the kept boxes of source frame `frame`; frames in increasing
    /// order): whether it goes through the network, and the number of the vehicle it belongs
    /// to (numbers are not reused).
    pub fn plan(&mut self, frame: u64, boxes: &[BoxPx]) -> Vec<(bool, u64)> {
        let s = self.settings;
        self.followed
            .retain(|f| frame.saturating_sub(f.last_frame) <= s.max_gap_frames);
        // Greedy matching, best overlap first.
        let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
        for (i, b) in boxes.iter().enumerate() {
            for (j, f) in self.followed.iter().enumerate() {
                let iou = b.iou(&f.last);
                if iou >= s.match_iou && f.last_frame < frame {
                    pairs.push((iou, i, j));
                }
            }
        }
        pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
        let mut owner: Vec<Option<usize>> = vec![None; boxes.len()];
        let mut taken = vec![false; self.followed.len()];
        for (_, i, j) in pairs {
            if owner[i].is_none() && !taken[j] {
                owner[i] = Some(j);
                taken[j] = true;
            }
        }
        boxes
            .iter()
            .zip(owner)
            .map(|(b, o)| {
                let area = b.width() * b.height();
                let j = o.unwrap_or_else(|| {
                    self.next_id += 1;
                    self.followed.push(Followed {
                        id: self.next_id - 1,
                        last: *b,
                        last_frame: frame,
                        seen: 0,
                        seen_at_crop: 0,
                        crops: 0,
                        largest_crop_area: 0.0,
                    });
                    self.followed.len() - 1
                });
                let f = &mut self.followed[j];
                f.last = *b;
                f.last_frame = frame;
                f.seen += 1;
                let grown = f.crops > 0 && area >= s.grow * f.largest_crop_area;
                let spread = f.crops == 0 || f.seen >= 2 * f.seen_at_crop;
                let send = grown || (spread && f.crops < s.max_crops);
                if send {
                    f.crops += u32::from(!grown);
                    f.seen_at_crop = f.seen;
                    f.largest_crop_area = f.largest_crop_area.max(area);
                }
                (send, f.id)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(x: f64, size: f64) -> BoxPx {
        BoxPx::new(x, 100.0, x + size, 100.0 + size * 0.6)
    }

    #[test]
    fn a_long_track_gets_a_few_crops_spread_over_it() {
        let mut p = CropPlanner::new(CropPlanSettings::for_step(1));
        let sent: Vec<u32> = (0..100u32)
            .filter(|&k| p.plan(u64::from(k), &[at(10.0 + 3.0 * f64::from(k), 80.0)])[0].0)
            .collect();
        assert_eq!(sent, vec![0, 1, 3, 7, 15, 31, 63], "{sent:?}");
    }

    #[test]
    fn a_growing_vehicle_is_sent_again_as_it_grows() {
        let mut p = CropPlanner::new(CropPlanSettings::for_step(1));
        let mut sizes = Vec::new();
        for k in 0..200u32 {
            let size = 20.0 * 1.02f64.powi(k as i32);
            let b = BoxPx::new(500.0 - size / 2.0, 300.0, 500.0 + size / 2.0, 300.0 + size);
            if p.plan(u64::from(k), &[b])[0].0 {
                sizes.push(size);
            }
        }
        // Area x 2600 over the track: about log(2600) / log(1.5) = 19 crops of growth, and
        // the largest box sent within a factor 1.5 in area of the last one seen.
        assert!((15..=26).contains(&sizes.len()), "{sizes:?}");
        assert!(sizes.windows(2).all(|w| w[1] > w[0]));
        let last = 20.0 * 1.02f64.powi(199);
        assert!(
            sizes[sizes.len() - 1].powi(2) * 1.5 >= last * last,
            "{sizes:?}"
        );
    }

    #[test]
    fn two_vehicles_are_followed_apart_and_a_gap_ends_a_vehicle() {
        let mut p = CropPlanner::new(CropPlanSettings::for_step(1));
        let (a, b) = (at(0.0, 50.0), at(400.0, 50.0));
        assert_eq!(p.plan(0, &[a, b]), vec![(true, 0), (true, 1)]);
        assert_eq!(
            p.plan(1, &[at(402.0, 50.0), at(2.0, 50.0)]),
            vec![(true, 1), (true, 0)]
        );
        assert_eq!(
            p.plan(2, &[at(4.0, 50.0), at(404.0, 50.0)]),
            vec![(false, 0), (false, 1)]
        );
        // Ten frames unseen: a new vehicle at the same place.
        assert_eq!(p.plan(13, &[at(6.0, 50.0)]), vec![(true, 2)]);
    }
}
