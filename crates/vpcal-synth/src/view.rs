//! What the camera must see clearly: props in the way are removed from a world.

use crate::camera::Camera;
use crate::math::{hull, V3};
use crate::raster::NEAR_M;
use crate::world::World;

/// Remove props that stand next to the camera or would fill a large part of the view.
pub fn clear_view(world: &mut World, cam: &Camera) {
    let area = f64::from(cam.width) * f64::from(cam.height);
    world.props.retain(|p| {
        let c = (p.lo + p.hi) * 0.5;
        let dxy = ((c.x - cam.position.x).powi(2) + (c.y - cam.position.y).powi(2)).sqrt();
        let radius = ((p.hi.x - p.lo.x).powi(2) + (p.hi.y - p.lo.y).powi(2)).sqrt() / 2.0;
        if dxy < radius + 6.0 && p.hi.z > cam.position.z - 3.0 {
            return false;
        }
        let mut pts = Vec::new();
        for x in [p.lo.x, p.hi.x] {
            for y in [p.lo.y, p.hi.y] {
                for z in [p.lo.z, p.hi.z] {
                    let q = cam.to_camera(V3::new(x, y, z));
                    if q.z < NEAR_M {
                        // Partly behind the camera: keep only if small and low.
                        if dxy < 40.0 {
                            return false;
                        }
                        continue;
                    }
                    if let Some(r) = cam.project_cam(q) {
                        pts.push(r);
                    }
                }
            }
        }
        if pts.is_empty() {
            return true;
        }
        let (x0, y0, x1, y1) = hull(&pts);
        let cw = (x1.min(f64::from(cam.width)) - x0.max(0.0)).max(0.0);
        let ch = (y1.min(f64::from(cam.height)) - y0.max(0.0)).max(0.0);
        // A thin pole may cross the frame; anything wide and tall in the view goes.
        cw * ch < 0.12 * area || cw < 0.04 * f64::from(cam.width)
    });
}
