//! The shipped weights (`fixtures/point2quad-default.p2qm`), loaded once per test binary:
//! real scores, so reconstructions compared in tests have many faces. Include with
//! `#[path = "common/shipped.rs"] mod shipped;`.
#![allow(dead_code)]

use point2quad::pipeline::model::Model;
use std::sync::OnceLock;

pub fn shipped() -> &'static Model {
    static M: OnceLock<Model> = OnceLock::new();
    M.get_or_init(|| {
        let p = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/point2quad-default.p2qm");
        Model::load(std::path::Path::new(p)).expect("test: shipped weights")
    })
}
