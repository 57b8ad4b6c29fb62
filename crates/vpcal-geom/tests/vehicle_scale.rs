#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The automatic metric scale: cuboids of known size on a known camera's road are recovered
//! from their image boxes alone.

use proptest::prelude::*;
use vpcal_geom::camera::Calibration;
use vpcal_geom::vehicle_scale::{
    cuboid_box, fit_cuboid, fit_vehicle, scale_from_vehicles, vehicle_box, Cabin, SizedBox,
    FLEET_LOG_SD, PASSENGER_CAR, PASSENGER_CAR_CABIN,
};
use vpcal_geom::Point2;

/// A 1920x1080 camera with focal length `f`, looking `tilt` below the horizon and `yaw`
/// across the road.
fn camera(f: f64, tilt_deg: f64, yaw_deg: f64) -> Calibration {
    let pp = Point2::new(960.0, 540.0);
    let (t, y) = (tilt_deg.to_radians(), yaw_deg.to_radians());
    // Camera coordinates: x right, y down, z forward. Road direction along the view, yawed.
    let along = [y.sin(), t.sin() * y.cos(), t.cos() * y.cos()];
    let across = [y.cos(), -t.sin() * y.sin(), -t.cos() * y.sin()];
    let vp = |d: [f64; 3]| Point2::new(pp.x + f * d[0] / d[2], pp.y + f * d[1] / d[2]);
    Calibration::from_vps(vp(along), vp(across), pp).unwrap()
}

#[test]
fn a_cuboid_is_recovered_from_its_image_box() {
    let cal = camera(1400.0, 18.0, 25.0);
    let h = cal.plane_distance();
    // A car 8 m-high camera's worth of units: metres per unit = 8 / h.
    let size = h / 8.0;
    let dims = PASSENGER_CAR.map(|d| d * size);
    for (i, centre) in [[3.0, 0.0], [5.0, 0.5], [2.0, -0.3]].iter().enumerate() {
        let c = [centre[0] * h, centre[1] * h];
        let b = cuboid_box(&cal, c, 0.0, dims).unwrap();
        let fit = fit_cuboid(&cal, b, 0.0, PASSENGER_CAR).unwrap();
        assert!(
            (fit.size / size - 1.0).abs() < 0.01,
            "{i}: {} vs {size}",
            fit.size
        );
        assert!(fit.rms < 1e-3, "{i}: {fit:?}");
    }
}

/// A car's outline (body and cabin) fits its own image exactly, lies inside its cuboid's box,
/// and a cuboid fit of it reads the car small: the bias the outline removes.
#[test]
fn a_car_outline_is_recovered_and_a_cuboid_reads_it_small() {
    // Looking 20° down at the road (VP1 above the principal point), 8° across it.
    let pp = Point2::new(960.0, 540.0);
    let (t, y) = (20f64.to_radians(), 8f64.to_radians());
    let along = [y.sin(), -t.sin() * y.cos(), t.cos() * y.cos()];
    let across = [y.cos(), t.sin() * y.sin(), -t.cos() * y.sin()];
    let vp = |d: [f64; 3]| Point2::new(pp.x + 1600.0 * d[0] / d[2], pp.y + 1600.0 * d[1] / d[2]);
    let cal = Calibration::from_vps(vp(along), vp(across), pp).unwrap();
    let h = cal.plane_distance();
    let size = h / 8.0;
    let dims = PASSENGER_CAR.map(|d| d * size);
    for centre in [[2.5, 0.1], [4.0, -0.3], [6.0, 0.4]] {
        let c = [centre[0] * h, centre[1] * h];
        let car = vehicle_box(&cal, c, 0.0, dims, PASSENGER_CAR_CABIN).unwrap();
        let cuboid = cuboid_box(&cal, c, 0.0, dims).unwrap();
        assert!(
            car.x0 >= cuboid.x0 && car.x1 <= cuboid.x1,
            "{car:?} {cuboid:?}"
        );
        assert!(
            car.y0 > cuboid.y0 && car.y1 <= cuboid.y1,
            "{car:?} {cuboid:?}"
        );
        let fit = fit_vehicle(&cal, car, 0.0, PASSENGER_CAR, PASSENGER_CAR_CABIN).unwrap();
        assert!(
            (fit.size / size - 1.0).abs() < 0.01,
            "{} vs {size}",
            fit.size
        );
        assert!(fit.rms < 1e-3, "{fit:?}");
        let as_cuboid = fit_cuboid(&cal, car, 0.0, PASSENGER_CAR).unwrap();
        assert!(as_cuboid.size < 0.97 * size, "{} vs {size}", as_cuboid.size);
    }
}

#[test]
fn the_scale_of_typical_cars_is_their_camera_height() {
    let cal = camera(1600.0, 15.0, 10.0);
    let h = cal.plane_distance();
    let height_m = 7.5;
    let size = h / height_m;
    let boxes: Vec<SizedBox> = (0..12)
        .filter_map(|i| {
            let c = [
                (2.5 + 0.4 * i as f64) * h,
                (i % 3) as f64 * 0.3 * h - 0.3 * h,
            ];
            let b = cuboid_box(&cal, c, 0.0, PASSENGER_CAR.map(|d| d * size))?;
            Some(SizedBox {
                bbox: b,
                heading: None,
                group: None,
            })
        })
        .collect();
    assert!(boxes.len() >= 10);
    let s =
        scale_from_vehicles(&cal, &boxes, 1920.0, 1080.0, PASSENGER_CAR, Cabin::NONE, 1).unwrap();
    let est_height = s.m_per_unit * h;
    assert!((est_height / height_m - 1.0).abs() < 0.01, "{s:?}");
    // The interval carries the fleet's spread even when the sample agrees exactly.
    let width = (s.interval[1] / s.interval[0]).ln();
    assert!(width >= 2.0 * FLEET_LOG_SD * 0.99, "{s:?}");
    // Too few vehicles: no scale.
    assert!(scale_from_vehicles(
        &cal,
        &boxes[..3],
        1920.0,
        1080.0,
        PASSENGER_CAR,
        Cabin::NONE,
        1
    )
    .is_none());
}

#[test]
fn boxes_cut_by_the_border_do_not_count() {
    let cal = camera(1600.0, 15.0, 10.0);
    let h = cal.plane_distance();
    let size = h / 7.5;
    let b = cuboid_box(&cal, [3.0 * h, 0.0], 0.0, PASSENGER_CAR.map(|d| d * size)).unwrap();
    let cut = vpcal_geom::BoxPx { x0: 0.0, ..b };
    let boxes = vec![
        SizedBox {
            bbox: cut,
            heading: None,
            group: None,
        };
        10
    ];
    assert!(
        scale_from_vehicles(&cal, &boxes, 1920.0, 1080.0, PASSENGER_CAR, Cabin::NONE, 1).is_none()
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// Any camera, place and heading: the fitted size is the cuboid's.
    #[test]
    fn fitted_size_matches(f in 800.0f64..3000.0, tilt in 8.0f64..40.0, yaw in -40.0f64..40.0,
                           ahead in 1.5f64..4.0, side in -0.4f64..0.4, heading in -1.5f64..1.5,
                           k in 0.7f64..1.4) {
        let cal = camera(f, tilt, yaw);
        let h = cal.plane_distance();
        let size = k * h / 8.0;
        let c = [ahead * h / tilt.to_radians().tan().max(0.2), side * h];
        let dims = PASSENGER_CAR.map(|d| d * size);
        let b = cuboid_box(&cal, c, heading, dims);
        prop_assume!(b.is_some_and(|b| b.is_valid() && b.width() > 8.0));
        let b = b.unwrap();
        let fit = fit_cuboid(&cal, b, heading, PASSENGER_CAR).unwrap();
        prop_assert!(fit.rms < 0.01, "{:?}", fit);
        prop_assert!((fit.size / size - 1.0).abs() < 0.03, "{} vs {}", fit.size, size);
    }
}

/// Boxes of a vehicle of `dims_m` driving along the road past `cal` (road x from 2 to 5
/// camera heights, at `lateral` heights across), with the camera `height_m` above the road.
fn track_boxes(
    cal: &Calibration,
    dims_m: [f64; 3],
    lateral: f64,
    height_m: f64,
) -> Vec<vpcal_geom::BoxPx> {
    let h = cal.plane_distance();
    let units = h / height_m;
    (0..20)
        .filter_map(|k| {
            let x = (2.0 + 0.15 * k as f64) * h;
            cuboid_box(cal, [x, lateral * h], 0.0, dims_m.map(|d| d * units))
        })
        .collect()
}

#[test]
fn a_track_gives_its_vehicles_length_and_height() {
    use vpcal_geom::vehicle_dims::{fit_dims, ASSUMED_WIDTH_M};
    for (f, tilt, yaw) in [
        (1400.0, 18.0, 25.0),
        (900.0, 12.0, -8.0),
        (2200.0, 25.0, 40.0),
    ] {
        let cal = camera(f, tilt, yaw);
        let height_m = 8.0;
        let units = cal.plane_distance() / height_m;
        // As wide as assumed: length and height exact.
        for dims in [[4.4, 1.8, 1.5], [3.6, 1.8, 1.45], [5.2, 1.8, 2.1]] {
            let boxes = track_boxes(&cal, dims, 0.2, height_m);
            let d = fit_dims(&cal, &boxes, ASSUMED_WIDTH_M * units, 0.0).unwrap();
            let (l, hh) = (d.length / units, d.height / units);
            assert!((l / dims[0] - 1.0).abs() < 0.03, "{f} {dims:?}: length {l}");
            assert!((d.width / units / dims[1] - 1.0).abs() < 0.03, "{d:?}");
            assert!(
                (hh / dims[2] - 1.0).abs() < 0.03,
                "{f} {dims:?}: height {hh}"
            );
            assert!(d.rms < 0.01, "{d:?}");
            let lateral = d.lateral / cal.plane_distance();
            assert!(
                (lateral - 0.2).abs() < 0.01,
                "{f} {dims:?}: lateral {lateral}"
            );
        }
        // A truck 2.5 m wide: read as a truck (the width prior pulls its width in, the
        // length makes up for it).
        let truck = [12.0, 2.5, 3.6];
        let boxes = track_boxes(&cal, truck, -0.3, height_m);
        let d = fit_dims(&cal, &boxes, ASSUMED_WIDTH_M * units, 0.0).unwrap();
        let (l, w, hh) = (d.length / units, d.width / units, d.height / units);
        assert!(w > 2.1 && w < 2.6, "{f}: truck width {w}");
        assert!(hh > 3.0 && hh < 4.0, "{f}: truck height {hh}");
        assert!(l > 10.5 && l < 14.5, "{f}: truck length {l}");
    }
}
