//! glTF 2.0 writer (being written).
