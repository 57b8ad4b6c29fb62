//! vpcal-geom: see the crate description.
