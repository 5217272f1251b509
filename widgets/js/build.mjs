// Bundles src/viewport.js (with three.js) into ../static/viewport.js as one minified ESM file.
// anywidget loads that file from the Python package: no CDN, no network at run time.
import * as esbuild from "esbuild";
import { fileURLToPath } from "node:url";
import path from "node:path";

const here = path.dirname(fileURLToPath(import.meta.url));
const options = {
  entryPoints: [path.join(here, "src", "viewport.js")],
  outfile: path.join(here, "..", "static", "viewport.js"),
  bundle: true,
  format: "esm",
  minify: true,
  target: ["es2020"],
  // keep three.js's MIT notice (and any other licence comment) at the end of the bundle
  legalComments: "eof",
  logLevel: "info",
};
// Second entry point: the keyframe timeline (plain DOM + canvas, no three.js).
const timelineOptions = {
  ...options,
  entryPoints: [path.join(here, "src", "timeline.js")],
  outfile: path.join(here, "..", "static", "timeline.js"),
};

// Third: the webcam of the Live tab (plain DOM, getUserMedia).
const cameraOptions = {
  ...options,
  entryPoints: [path.join(here, "src", "camera.js")],
  outfile: path.join(here, "..", "static", "camera.js"),
};

if (process.argv.includes("--watch")) {
  const ctx = await esbuild.context(options);
  await ctx.watch();
  await (await esbuild.context(timelineOptions)).watch();
  await (await esbuild.context(cameraOptions)).watch();
} else {
  await esbuild.build(options);
  await esbuild.build(timelineOptions);
  await esbuild.build(cameraOptions);
}
