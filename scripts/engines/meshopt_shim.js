// Babylon.js loads this script before it uses the global MeshoptDecoder (EXT_meshopt_compression);
// babylon.html has already set that global from the decoder three.js ships, so nothing is left to do.
