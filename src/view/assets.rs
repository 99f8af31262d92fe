//! The page and its scripts, compiled into the binary (so `cargo install` needs no npm), served
//! at fixed paths: the only files the server has.
//!
//! three.js r170 (`three@0.170.0` from npm: `build/three.module.min.js` and the three
//! `examples/jsm` modules the page imports, unchanged; MIT, `vendor/three/LICENSE`).

/// One asset: its URL path, MIME type and content.
pub struct Asset {
    pub path: &'static str,
    pub content_type: &'static str,
    pub bytes: &'static [u8],
}

const JS: &str = "text/javascript; charset=utf-8";

macro_rules! asset {
    ($path:literal, $type:expr) => {
        Asset {
            path: $path,
            content_type: $type,
            bytes: include_bytes!(concat!("web", $path)),
        }
    };
}

pub const ASSETS: &[Asset] = &[
    Asset {
        path: "/",
        content_type: "text/html; charset=utf-8",
        bytes: include_bytes!("web/index.html"),
    },
    asset!("/viewer.js", JS),
    asset!("/viewer.css", "text/css; charset=utf-8"),
    // `imubake setup`'s page (at `/` in a setup session).
    asset!("/setup.html", "text/html; charset=utf-8"),
    asset!("/setup.js", JS),
    asset!("/setup.css", "text/css; charset=utf-8"),
    asset!("/vendor/three/three.module.min.js", JS),
    asset!("/vendor/three/addons/loaders/GLTFLoader.js", JS),
    asset!("/vendor/three/addons/controls/OrbitControls.js", JS),
    asset!("/vendor/three/addons/utils/BufferGeometryUtils.js", JS),
    asset!("/vendor/three/LICENSE", "text/plain; charset=utf-8"),
];

/// The asset at exactly `path` (`/index.html` is `/`).
pub fn find(path: &str) -> Option<&'static Asset> {
    let path = if path == "/index.html" { "/" } else { path };
    ASSETS.iter().find(|a| a.path == path)
}
