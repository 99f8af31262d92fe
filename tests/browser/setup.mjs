#!/usr/bin/env node
// Drives `imubake setup`'s page in Debian's Chromium (headless) with playwright-core against the
// replayed stream of tests/python/setup_stream.py, as a user would: for each slot of the stream
// it waits for a sensor to light up, clicks its row and then the bone the truth says moves in
// that slot (it is never told which sensor that is); it runs the gyro-bias capture, holds the
// pose, bows, enters a segment, runs the magnetometer capture, enters a height and saves. Prints
// JSON on stdout.
//
//   node tests/browser/setup.mjs URL TRUTH.json SHOT.png
//
// URL `-`: the browser is started first, `ready` printed on a line of its own, and the URL read
// from a line of stdin — the stream replays in real time from the server's start, and a
// browser starting on a loaded machine can take longer than the stream's still lead-in.
//
// Output (after `ready`, when URL is `-`): {"console": [...], "failed": [...], "slots": [{"bone", "start_s", "lit", "seen_at_s"}],
// "state": the page's last board, "message": the page's message after Save}.
//   IMUBAKE_NODE_MODULES  node_modules holding playwright-core (scripts/test.sh installs it)
//   IMUBAKE_CHROMIUM      the browser (default /usr/bin/chromium)
import { createRequire } from "node:module";
import { createInterface } from "node:readline";
import { readFileSync } from "node:fs";
import path from "node:path";

const modules = process.env.IMUBAKE_NODE_MODULES;
const require = createRequire(modules ? path.join(modules, "noop.js") : import.meta.url);
const { chromium } = require("playwright-core");

const [url, truthPath, shot] = process.argv.slice(2);
const truth = JSON.parse(readFileSync(truthPath, "utf8"));
const browser = await chromium.launch({
  executablePath: process.env.IMUBAKE_CHROMIUM || "/usr/bin/chromium",
  headless: true,
  args: ["--no-sandbox", "--no-first-run", "--disable-background-networking", "--disable-component-update", "--disable-sync"],
});
const out = { console: [], failed: [], slots: [], state: null, message: null };
try {
  const page = await browser.newPage({ viewport: { width: 1600, height: 900 }, deviceScaleFactor: 1 });
  page.on("console", (m) => {
    if (m.type() === "error" || m.type() === "warning") out.console.push(`${m.type()}: ${m.text()}`);
  });
  page.on("pageerror", (e) => out.console.push(`pageerror: ${e.message}`));
  page.on("requestfailed", (r) => out.failed.push(`${r.url()}: ${r.failure()?.errorText}`));
  page.on("response", (r) => { if (r.status() >= 400) out.failed.push(`${r.url()}: ${r.status()}`); });
  let target = url;
  if (url === "-") {
    process.stdout.write("ready\n");
    const stdin = createInterface({ input: process.stdin });
    target = (await stdin[Symbol.asyncIterator]().next()).value?.trim();
    stdin.close();
    if (!target) throw new Error("no URL on stdin");
  }
  await page.goto(target);
  const now = () => page.evaluate(() => window.imubakeSetup.state?.now_s ?? -1);
  // Stream time (seconds), polled: the board's latest sample.
  const until = async (t, limit_s = 120) => {
    const deadline = Date.now() + limit_s * 1000;
    while ((await now()) < t) {
      if (Date.now() > deadline) throw new Error(`the stream never reached t = ${t} s`);
      await page.waitForTimeout(20);
    }
  };
  const board = (test, what, limit_s = 20) =>
    page.waitForFunction(test, null, { timeout: limit_s * 1000, polling: 50 }).catch(() => {
      throw new Error(`waited ${limit_s} s for ${what}`);
    });

  for (const move of truth.moves) {
    await until(move.start_s - 0.3);
    // The first row lit after the slot starts: what the user sees light up.
    let lit = null;
    let seen = null;
    const deadline = Date.now() + 3000;
    while (lit === null && Date.now() < deadline) {
      const [row, t] = await page.evaluate(() => [
        document.querySelector("#sensors tr.lit")?.dataset.sensor ?? null,
        window.imubakeSetup.state.now_s,
      ]);
      if (row !== null && t >= move.start_s) [lit, seen] = [row, t];
      else await page.waitForTimeout(10);
    }
    out.slots.push({ bone: move.bone, start_s: move.start_s, lit, seen_at_s: seen });
    if (lit === null) continue;
    await page.click(`#sensors tr[data-sensor="${lit}"]`);
    await page.click(`#figure polygon[data-bone="${move.bone}"]`);
  }

  await until(truth.bias_phase_s[0] + 0.3);
  await page.click("#bias");
  await board(() => window.imubakeSetup.state.bias.length > 0, "the gyro bias");
  await until(truth.pose_phase_s[0] + 0.2);
  await page.click("#hold");
  await board(() => window.imubakeSetup.state.pose_held !== null, "the pose");
  await until(truth.bow_phase_s[0] + 0.2);
  await page.click("#bow");
  await board(() => window.imubakeSetup.state.bow !== null, "the bow");
  await page.selectOption("#segment-part", "left_thigh");
  await page.fill("#segment-m", "0.45");
  await page.click("#set-segment");
  await board(() => window.imubakeSetup.state.segments.left_thigh === 0.45, "the segment");
  await until(truth.mag_phase_s[0] + 0.1);
  await page.click("#mag");
  await board(() => window.imubakeSetup.state.mag.length > 0, "the magnetometers", 30);
  await page.fill("#height", "1.72");
  await page.click("#set-height");
  await board(() => window.imubakeSetup.state.height_m !== null, "the height");
  await page.click("#save");
  await board(() => (window.imubakeSetup.state.message ?? "").startsWith("saved"), "the save", 10);
  out.message = await page.evaluate(() => document.getElementById("message").textContent);
  out.state = await page.evaluate(() => window.imubakeSetup.state);
  for (const camera of ["side", "top", "follow", "front"]) await page.click(`#cameras button[data-camera="${camera}"]`);
  await page.screenshot({ path: shot });
  out.errors = await page.evaluate(() => window.imubakeSetup.errors);
} catch (e) {
  out.console.push(`driver: ${e.message}`);
} finally {
  await browser.close();
}
process.stdout.write(JSON.stringify(out));
