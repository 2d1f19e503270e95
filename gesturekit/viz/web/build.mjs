// Bundles src/viewer.js and the three.js it imports (node_modules, from package-lock.json) into one minified
// ES module: node build.mjs OUT [ENTRY]. ENTRY (default src/viewer.js) may be another module, anywhere, that
// imports the same npm packages (a test's page, say): they are found in this folder's node_modules.
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";
import { build } from "esbuild";

const here = dirname(fileURLToPath(import.meta.url));

await build({
  entryPoints: [process.argv[3] ?? join(here, "src", "viewer.js")],
  bundle: true,
  minify: true,
  format: "esm",
  target: "es2020",
  legalComments: "eof",  // three.js's licence notice travels with it,
  nodePaths: [join(here, "node_modules")],
  outfile: process.argv[2],
  logLevel: "warning",
});
