#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Linking boxes into tracks and fitting their VP1 lines.

use proptest::prelude::*;
use vpcal_geom::aggregate::tracks::{fit_line, link, tangents, track_lines, TrackOptions};
use vpcal_geom::{BoxPx, Point2};

/// A box of half size `half` (aspect 0.7) centred on `c`.
fn box_at(c: Point2, half: f64) -> BoxPx {
    BoxPx::new(c.x - half, c.y - 0.7 * half, c.x + half, c.y + 0.7 * half)
}

/// A vehicle driving away towards `vp`: at step `k` its centre is `start` moved towards `vp`
/// by the perspective factor `s = 1 / (1 + 0.03 k)`, and its box shrinks by the same factor.
fn receding(vp: Point2, start: Point2, half: f64, k: usize) -> BoxPx {
    let s = 1.0 / (1.0 + 0.03 * k as f64);
    box_at(vp + (start - vp) * s, half * s)
}

fn angle_to(line_point: Point2, dir: Point2, target: Point2) -> f64 {
    let t = target - line_point;
    let cross = dir.x * t.y - dir.y * t.x;
    (cross / t.norm()).abs().asin().to_degrees()
}

#[test]
fn two_interleaved_vehicles_give_two_lines_through_vp1() {
    let vp = Point2::new(1200.0, -150.0);
    let starts = [Point2::new(500.0, 900.0), Point2::new(1500.0, 950.0)];
    let mut boxes = Vec::new();
    for k in 0..15 {
        for s in starts {
            boxes.push((k as f64, receding(vp, s, 80.0, k)));
        }
    }
    let tracks = link(&boxes, &TrackOptions::default());
    assert_eq!(tracks.len(), 2, "{tracks:?}");
    for t in &tracks {
        assert_eq!(t.len(), 15);
        // One vehicle per track: all boxes of a track start from the same side.
        let side = boxes[t[0]].1.center().x < 1000.0;
        assert!(t.iter().all(|&i| (boxes[i].1.center().x < 1000.0) == side));
    }
    let lines = track_lines(&boxes, &TrackOptions::default());
    assert_eq!(lines.len(), 2);
    for l in lines {
        assert!(angle_to(l.point, l.dir, vp) < 1e-6, "{l:?}");
        assert!(l.rms < 1e-6 && l.travel > 100.0, "{l:?}");
    }
}

#[test]
fn parked_turning_and_short_tracks_give_no_line() {
    let opts = TrackOptions::default();
    // Parked: the same place in 20 frames.
    let parked: Vec<(f64, BoxPx)> = (0..20)
        .map(|k| (k as f64, box_at(Point2::new(300.0, 300.0), 40.0)))
        .collect();
    let t = link(&parked, &opts);
    assert_eq!(t.len(), 1);
    assert!(fit_line(&parked, &t[0], &opts).is_none());
    // Turning: a quarter circle of radius 400 px.
    let turning: Vec<(f64, BoxPx)> = (0..20)
        .map(|k| {
            let a = k as f64 / 19.0 * std::f64::consts::FRAC_PI_2;
            let c = Point2::new(400.0 * a.cos(), 400.0 * a.sin());
            (k as f64, box_at(c, 60.0))
        })
        .collect();
    let t = link(&turning, &opts);
    assert_eq!(t.len(), 1, "the turn is one track");
    assert!(fit_line(&turning, &t[0], &opts).is_none());
    // Too few boxes.
    let short = &turning[..3];
    assert!(track_lines(short, &opts).is_empty());
}

#[test]
fn boxes_too_far_apart_in_time_do_not_link() {
    // Sparse frames: the vehicle moves several box sizes between samples.
    let boxes: Vec<(f64, BoxPx)> = (0..10)
        .map(|k| {
            (
                50.0 * k as f64,
                box_at(Point2::new(100.0 + 150.0 * k as f64, 500.0), 30.0),
            )
        })
        .collect();
    let tracks = link(&boxes, &TrackOptions::default());
    assert_eq!(tracks.len(), 10);
    assert!(track_lines(&boxes, &TrackOptions::default()).is_empty());
}

#[test]
fn a_track_survives_a_missed_detection() {
    let vp = Point2::new(900.0, -300.0);
    let boxes: Vec<(f64, BoxPx)> = (0..12)
        .filter(|&k| k != 5)
        .map(|k| (k as f64, receding(vp, Point2::new(700.0, 800.0), 60.0, k)))
        .collect();
    let tracks = link(&boxes, &TrackOptions::default());
    assert_eq!(tracks.len(), 1);
    assert_eq!(tracks[0].len(), 11);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, .. ProptestConfig::default() })]
    #[test]
    fn every_valid_box_is_in_exactly_one_track(
        raw in prop::collection::vec((0u8..20, 0.0f64..500.0, 0.0f64..500.0, 5.0f64..80.0), 0..80)
    ) {
        let boxes: Vec<(f64, BoxPx)> = raw
            .iter()
            .map(|&(f, x, y, s)| (f as f64, BoxPx::new(x, y, x + s, y + 0.8 * s)))
            .collect();
        let tracks = link(&boxes, &TrackOptions::default());
        let mut seen: Vec<usize> = tracks.iter().flatten().copied().collect();
        seen.sort_unstable();
        prop_assert_eq!(seen, (0..boxes.len()).collect::<Vec<_>>());
        for t in &tracks {
            prop_assert!(!t.is_empty());
            // Frames strictly increase along a track (one box per frame).
            prop_assert!(t.windows(2).all(|w| boxes[w[0]].0 < boxes[w[1]].0));
        }
    }
}

#[test]
fn a_car_moving_most_of_its_length_between_samples_still_links() {
    // 45 px per step with boxes 60 x 42 (size 50): successive boxes overlap with IoU 0.14,
    // too little to start a track; the size-and-distance rule starts it, the velocity
    // carries it.
    let boxes: Vec<(f64, BoxPx)> = (0..8)
        .map(|k| {
            (
                5.0 * k as f64,
                box_at(Point2::new(100.0 + 45.0 * k as f64, 500.0), 30.0),
            )
        })
        .collect();
    let opts = TrackOptions::default();
    assert_eq!(link(&boxes, &opts), vec![(0..8).collect::<Vec<_>>()]);
    let strict = TrackOptions {
        first_link_sizes: 0.0,
        ..opts
    };
    assert_eq!(link(&boxes, &strict).len(), 8);
}

#[test]
fn a_track_on_a_curve_bends_significantly_and_a_noisy_straight_one_does_not() {
    let opts = TrackOptions::default();
    let track: Vec<usize> = (0..20).collect();
    // Straight, receding, with ±1.5 px of deterministic jitter across the track.
    let vp = Point2::new(900.0, -100.0);
    let straight: Vec<(f64, BoxPx)> = (0..20)
        .map(|k| {
            let b = receding(vp, Point2::new(400.0, 900.0), 60.0, k);
            let j = 1.5 * ((k * 7919 % 13) as f64 / 6.0 - 1.0);
            (k as f64, BoxPx::new(b.x0 + j, b.y0, b.x1 + j, b.y1))
        })
        .collect();
    let line = fit_line(&straight, &track, &opts).unwrap();
    assert!(line.bend_t.abs() < 4.0, "{line:?}");
    // An arc of radius 6000 px over 12° (sagitta ~33 px on 1250 px of travel) passes the
    // straightness test (RMS < 3 % of the travel) but bends with a large t.
    let arc = |sign: f64| -> Vec<(f64, BoxPx)> {
        (0..20)
            .map(|k| {
                let a = (-6.0 + 12.0 * k as f64 / 19.0).to_radians();
                let c = Point2::new(
                    600.0 + sign * 6000.0 * (1.0 - a.cos()),
                    500.0 + 6000.0 * a.sin(),
                );
                (k as f64, box_at(c, 40.0))
            })
            .collect()
    };
    let right = fit_line(&arc(1.0), &track, &opts).unwrap();
    let left = fit_line(&arc(-1.0), &track, &opts).unwrap();
    assert!(right.bend_t.abs() > 100.0, "{right:?}");
    assert!(left.bend_t.abs() > 100.0, "{left:?}");
    // Mirror images bend to opposite sides of the same direction.
    let s = right.dir.dot(left.dir).signum();
    assert!(right.bend_t * left.bend_t * s < 0.0, "{right:?} {left:?}");
}

#[test]
fn far_small_boxes_and_boxes_cut_by_the_frame_do_not_bend_a_straight_track() {
    let vp = Point2::new(900.0, -100.0);
    let track: Vec<usize> = (0..40).collect();
    // A car receding along a straight lane (40 boxes, 60 px half width shrinking to 13 px).
    let straight: Vec<(f64, BoxPx)> = (0..40)
        .map(|k| {
            (
                k as f64,
                receding(vp, Point2::new(400.0, 900.0), 60.0, 3 * k),
            )
        })
        .collect();
    // Far away (boxes under a third of the nearest one's height) the detector's box slides
    // sideways with the traffic around it: up to 12 px over the last boxes.
    let drifting: Vec<(f64, BoxPx)> = straight
        .iter()
        .map(|&(f, b)| {
            let shrink = b.height() / straight[0].1.height();
            let slide = if shrink < 0.3 {
                12.0 * (0.3 - shrink) / 0.1
            } else {
                0.0
            };
            (f, BoxPx::new(b.x0 + slide, b.y0, b.x1 + slide, b.y1))
        })
        .collect();
    let opts = TrackOptions::default();
    let line = fit_line(&drifting, &track, &opts).unwrap();
    assert!(line.bend_t.abs() < 4.0, "{line:?}");
    // A car coming nearer in a lane that leaves the frame at its left edge: its nearest boxes
    // are cut there, and their centres move right, across the track.
    let approaching: Vec<(f64, BoxPx)> = (0..40)
        .map(|k| {
            let g = 0.3 + 0.6 * k as f64 / 39.0;
            let b = box_at(vp + (Point2::new(-200.0, 1100.0) - vp) * g, 80.0 * g);
            (
                k as f64,
                BoxPx::new(b.x0.max(0.0), b.y0, b.x1, b.y1.min(1080.0)),
            )
        })
        .collect();
    let unframed = fit_line(&approaching, &track, &opts).unwrap();
    assert!(unframed.bend_t.abs() > 4.0, "{unframed:?}");
    let framed = TrackOptions {
        frame: Some([1920.0, 1080.0]),
        ..opts.clone()
    };
    let line = fit_line(&approaching, &track, &framed).unwrap();
    assert!(line.bend_t.abs() < 4.0, "{line:?}");
}

#[test]
fn a_tangent_knows_its_error_from_the_boxes_jitter() {
    // One car, 30 boxes 10 px apart along x; exact centres, then centres jittering 2 px up and
    // down. The window (4 boxes either side: 9 centres, RMS spread 25.8 px along the axis)
    // turns that jitter into a slope error of about 2 / (25.8 sqrt 7) rad = 1.7°.
    let track: Vec<usize> = (0..30).collect();
    for (jitter, lo, hi) in [(0.0, 0.0, 1e-9), (2.0, 1.2, 2.2)] {
        let boxes: Vec<(f64, BoxPx)> = (0..30)
            .map(|k| {
                let y = 300.0 + if k % 2 == 0 { jitter } else { -jitter };
                (
                    k as f64,
                    box_at(Point2::new(100.0 + 10.0 * k as f64, y), 30.0),
                )
            })
            .collect();
        let t = tangents(&boxes, std::slice::from_ref(&track), 4, 3.0);
        assert!(t[..4].iter().chain(&t[26..]).all(Option::is_none));
        for tangent in t[4..26].iter().map(|t| t.unwrap()) {
            let se = tangent.se_rad.to_degrees();
            assert!((lo..=hi).contains(&se), "jitter {jitter}: se {se}°");
            assert!(tangent.dir.y.abs() < 0.05, "{:?}", tangent.dir);
        }
    }
}
