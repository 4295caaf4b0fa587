//! Writers: glTF 2.0 (.glb, .gltf + .bin), OBJ + MTL, tables. All writes are atomic.
