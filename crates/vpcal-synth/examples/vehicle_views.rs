//! Render every vehicle class from a few viewpoints on a plain road, to inspect the models:
//! `cargo run --release -p vpcal-synth --example vehicle_views -- OUT.png [SEED]`.

use std::f64::consts::PI;

use vpcal_synth::camera::Camera;
use vpcal_synth::math::{rng_for, V3};
use vpcal_synth::mesh::Pose;
use vpcal_synth::raster::{Backdrop, Target};
use vpcal_synth::shade::Lighting;
use vpcal_synth::vehicle::{VehicleKind, VehicleSpec};
use vpcal_synth::world::{generate_world, LayoutKind, WorldParams};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let out = args.get(1).map_or("vehicle_views.png", String::as_str);
    let seed: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(0);
    let kinds = [
        VehicleKind::Sedan,
        VehicleKind::Hatchback,
        VehicleKind::Wagon,
        VehicleKind::Suv,
        VehicleKind::Pickup,
        VehicleKind::Van,
        VehicleKind::Truck,
        VehicleKind::Bus,
    ];
    let views: Vec<f64> = std::env::args()
        .nth(3)
        .map_or(vec![0.35, 1.2, 2.2, 3.0, -0.8], |s| {
            s.split(",").filter_map(|v| v.parse().ok()).collect()
        });
    let cell: u32 = std::env::var("CELL")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(240);
    let mut sheet = image::RgbImage::new(cell * views.len() as u32, cell * kinds.len() as u32);
    let mut rng = rng_for(seed, &[1]);
    let world = generate_world(
        &mut rng,
        WorldParams {
            layout: LayoutKind::Highway,
            focus: [0.0, 0.0],
            heading: 0.0,
            clutter: 0.0,
        },
    );
    let mut light = Lighting::random(&mut rng);
    light.exposure = 1.0 / light.ground_irradiance(0.0)[1];
    for (row, kind) in kinds.iter().enumerate() {
        let spec = VehicleSpec::random(&mut rng_for(seed, &[row as u64]), *kind);
        let model = spec.build_model();
        let dist = spec.length.max(4.0) * 2.6;
        for (col, az) in views.iter().enumerate() {
            // Camera on a circle around the vehicle, 30 degrees above it, looking at its centre.
            let elev: f64 = std::env::args()
                .nth(4)
                .and_then(|s| s.parse().ok())
                .unwrap_or(0.5);
            let pos = V3::new(
                dist * az.cos() * elev.cos(),
                dist * az.sin() * elev.cos(),
                dist * elev.sin() + 0.5,
            );
            let yaw = az + PI;
            let pitch = ((pos.z - spec.height / 2.0) / (dist * elev.cos())).atan();
            let f = f64::from(cell) * 2.4;
            let cam = Camera::from_angles(cell, cell, f, pos, yaw, pitch, 0.0);
            let pose = Pose {
                x: 0.0,
                y: 0.0,
                heading: 0.0,
            };
            let mut t = Target::new(0.0, 0.0, cell as usize, cell as usize, 2);
            t.draw(&cam, &light, &model.mesh.placed(&pose).tris, 1);
            t.draw_shadow(&cam, &light, &model.shadow.placed(&pose).tris);
            t.draw_contact_shadow(&cam, &pose, spec.length, spec.width, 0.5);
            t.fill_background(&cam, &light, Backdrop::World(&world));
            let img = t.resolve(&light);
            image::imageops::replace(
                &mut sheet,
                &img,
                i64::from(col as u32 * cell),
                i64::from(row as u32 * cell),
            );
        }
    }
    sheet.save(out)?;
    println!("{out}");
    Ok(())
}
