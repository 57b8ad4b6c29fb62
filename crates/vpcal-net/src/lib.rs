//! vpcal-net: see the crate description.
