// Bundles src/viewer.js and the three.js it imports (node_modules, from package-lock.json) into one minified
// ES module: node build.mjs OUT
import { build } from "esbuild";

await build({
  entryPoints: ["src/viewer.js"],
  bundle: true,
  minify: true,
  format: "esm",
  target: "es2020",
  legalComments: "eof",  // three.js's licence notice travels with it,
  outfile: process.argv[2],
  logLevel: "warning",
});
