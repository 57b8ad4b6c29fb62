//! Benchmark (not a test): aggregation time of 100 000 real per-vehicle VP pairs, robust
//! against the reference rule in the same run.
//!
//! The pairs are the real CNN outputs of one BrnoCompSpeed video, repeated with their frame
//! numbers shifted by the length of the video (so each copy is new traffic, not a parked car)
//! until there are at least `N` of them.
//!
//! ```sh
//! cargo run --release -p vpcal --example bench_aggregate -- \
//!     ../shared/data/bcs/vp_outputs/session0_center/VPout_VP1VP2b_pd_aug_25.0ps_10cd_128in_128out_0.03-0.1-0.3-1.0s_2n_4b_256c_9_r60.json 100000
//! ```
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::time::Instant;

use vpcal_formats::reference::read_vpout;
use vpcal_geom::aggregate::reference::{self, ReferenceOptions};
use vpcal_geom::aggregate::robust::{self, RobustOptions};
use vpcal_geom::aggregate::VehicleVps;
use vpcal_geom::Point2;

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().expect("usage: bench_aggregate VPOUT.json [N]");
    let n: usize = args.next().map_or(100_000, |s| s.parse().expect("N"));
    let items = read_vpout(std::path::Path::new(&path)).expect("read VPout");
    let base: Vec<VehicleVps> = items.iter().map(|i| i.to_vehicle()).collect();
    let span = base.iter().filter_map(|v| v.frame).fold(0.0f64, f64::max) + 1000.0;
    let mut vehicles = Vec::with_capacity(n);
    let mut copy = 0.0;
    while vehicles.len() < n {
        for v in &base {
            let mut v = *v;
            v.frame = v.frame.map(|f| f + copy * span);
            vehicles.push(v);
        }
        copy += 1.0;
    }
    vehicles.truncate(n);
    let pp = Point2::new(960.5, 540.5);
    let time = |f: &dyn Fn()| {
        let mut t = Vec::new();
        for _ in 0..3 {
            let s = Instant::now();
            f();
            t.push(s.elapsed().as_secs_f64());
        }
        t.sort_by(f64::total_cmp);
        t[1]
    };
    let t_ref = time(&|| {
        reference::aggregate(&vehicles, pp, &ReferenceOptions { min_score: 0.1 }).unwrap();
    });
    let robust_opts = |bootstrap| RobustOptions {
        image_size: Some([1920.0, 1080.0]),
        bootstrap,
        ..RobustOptions::default()
    };
    let t_rob = time(&|| {
        robust::aggregate(&vehicles, pp, &robust_opts(0)).unwrap();
    });
    let t_boot = time(&|| {
        robust::aggregate(&vehicles, pp, &robust_opts(30)).unwrap();
    });
    println!(
        "{} pairs ({} real, repeated): reference {:.3} s, robust {:.3} s ({:.1}x reference), \
         robust + 30 bootstrap resamples {:.3} s (median of 3)",
        vehicles.len(),
        base.len(),
        t_ref,
        t_rob,
        t_rob / t_ref,
        t_boot
    );
}
