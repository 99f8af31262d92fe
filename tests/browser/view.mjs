#!/usr/bin/env node
// Drives the viewer page in Debian's Chromium (headless, WebGL through SwiftShader) with
// playwright-core and prints what the page shows as JSON on stdout.
//
//   node tests/browser/view.mjs take URL SHOTS_DIR FRAME...
//     opens URL#frame=<first>&follow=0, then moves to each further frame through the address's
//     fragment (no reload, the camera stays); per frame: the hook's frame and time, the counter
//     and time texts, the joints' world positions (metres) and screen positions (CSS pixels),
//     and a screenshot SHOTS_DIR/frame-<N>.png.
//   node tests/browser/view.mjs live URL MIN_FRAME
//     opens URL, waits for a live pose at or after MIN_FRAME, and reads that pose's joints.
//
// Output: {"console": [every console message of type error or warning, and page errors],
// "failed": [requests that failed or got ≥ 400], "frames": [...]}.
//   IMUBAKE_NODE_MODULES  node_modules holding playwright-core (scripts/test.sh installs it)
//   IMUBAKE_CHROMIUM      the browser (default /usr/bin/chromium)
import { createRequire } from "node:module";
import path from "node:path";

const modules = process.env.IMUBAKE_NODE_MODULES;
const require = createRequire(modules ? path.join(modules, "noop.js") : import.meta.url);
const { chromium } = require("playwright-core");

const [mode, url, ...rest] = process.argv.slice(2);
const browser = await chromium.launch({
  executablePath: process.env.IMUBAKE_CHROMIUM || "/usr/bin/chromium",
  headless: true,
  args: [
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--no-sandbox",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
  ],
});
const out = { console: [], failed: [], frames: [] };
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 720 }, deviceScaleFactor: 1 });
  page.on("console", (m) => {
    if (m.type() === "error" || m.type() === "warning") out.console.push(`${m.type()}: ${m.text()}`);
  });
  page.on("pageerror", (e) => out.console.push(`pageerror: ${e.message}`));
  // A fetch the page read to its end through a stream (three.js's FileLoader) is sometimes
  // reported as ERR_ABORTED afterwards; the page's own errors and HTTP statuses tell real failures.
  page.on("requestfailed", (r) => {
    if (r.failure()?.errorText !== "net::ERR_ABORTED") out.failed.push(`${r.url()}: ${r.failure()?.errorText}`);
  });
  page.on("response", (r) => { if (r.status() >= 400) out.failed.push(`${r.url()}: ${r.status()}`); });

  const read = () =>
    page.evaluate(() => {
      const h = window.imubake;
      return {
        frame: h.frame,
        live_frame: h.live_frame,
        time_s: h.time_s,
        counter: document.getElementById("counter").textContent,
        time_text: document.getElementById("time").textContent,
        joints: h.joints,
        bones: h.bones(),
        screen: h.screen(),
        errors: h.errors,
      };
    });
  // Two animation frames: the pose shown has been drawn.
  const drawn = () =>
    page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));

  if (mode === "take") {
    const [shots, ...frames] = rest;
    const wanted = frames.map(Number);
    await page.goto(`${url}#frame=${wanted[0]}&follow=0`, { waitUntil: "load" });
    await page.waitForFunction(() => window.imubake && (window.imubake.ready || window.imubake.errors.length), null, { timeout: 60000 });
    for (const [i, n] of wanted.entries()) {
      if (i > 0) {
        await page.evaluate((n) => { location.hash = `#frame=${n}&follow=0`; }, n);
        await page.waitForFunction((n) => window.imubake.frame === n, n, { timeout: 60000 });
      }
      await drawn();
      const state = await read();
      state.shot = path.join(shots, `frame-${n}.png`);
      await page.screenshot({ path: state.shot });
      out.frames.push(state);
    }
  } else if (mode === "live") {
    const min = Number(rest[0]);
    await page.goto(url, { waitUntil: "load" });
    await page.waitForFunction((min) => window.imubake && (window.imubake.live_frame >= min || window.imubake.errors.length), min, { timeout: 60000 });
    out.frames.push(await read());
    out.status = await page.evaluate(() => document.getElementById("live-status").textContent);
  } else {
    throw new Error(`unknown mode ${mode}`);
  }
} finally {
  await browser.close();
}
process.stdout.write(JSON.stringify(out));
