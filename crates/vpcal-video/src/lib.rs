//! vpcal-video: see the crate description.
