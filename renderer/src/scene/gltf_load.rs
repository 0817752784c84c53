//! glTF 2.0 loading (.gltf and .glb). (Being written.)
