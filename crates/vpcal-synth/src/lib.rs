//! vpcal-synth: see the crate description.
