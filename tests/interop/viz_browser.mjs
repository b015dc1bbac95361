// Opens the live view's page in Debian's Chromium (headless, driven by playwright-core; no browser is
// downloaded) and waits until it has drawn what is asked; then keeps a screenshot and prints what the page
// drew, with a count of the canvas's pixels in the trajectory's and the loops' colours, as JSON.
//   node viz_browser.mjs URL SCREENSHOT [--poses N] [--loops K] [--robots R] [--keyframe] [--timeout S] [--then-stdin]
// With --then-stdin, once the first condition holds it prints {"live": ...} and reads a line of JSON from stdin
// with the next condition's values ({"poses": 259, "loops": 310, "exact": true}: exact asks for those counts,
// not at least), and waits for that before the screenshot. On timeout it still takes the screenshot, prints what
// there was with "timeout": true and exits 1.
import { chromium } from "playwright-core";
import { createInterface } from "node:readline";

const [url, screenshot, ...rest] = process.argv.slice(2);
const opt = (name, fallback) => {
  const i = rest.indexOf(name);
  return i < 0 ? fallback : rest[i + 1];
};
const want = { poses: Number(opt("--poses", "1")), loops: Number(opt("--loops", "0")),
               robots: Number(opt("--robots", "1")), keyframe: rest.includes("--keyframe"), exact: false };
const lines = createInterface({ input: process.stdin })[Symbol.asyncIterator]();
const timeoutMs = Number(opt("--timeout", "120")) * 1000;

const browser = await chromium.launch({
  executablePath: process.env.SGLC_CHROMIUM ?? "/usr/bin/chromium",
  headless: true,
  // root in a container has no user namespace for Chromium's sandbox
  args: ["--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage"],
});
let timedOut = false;
try {
  const page = await browser.newPage({ viewport: { width: 1200, height: 800 } });
  const errors = [];
  page.on("pageerror", (e) => errors.push(String(e)));
  page.on("console", (m) => m.type() === "error" && errors.push(m.text()));
  await page.goto(url);
  const reached = async (w) => {
    try {
      await page.waitForFunction((w) => {
        const v = window.sglcView;
        const enough = (have, need) => (w.exact ? have === need : have >= need);
        return v && v.connected && enough(v.drawn.poses, w.poses) && enough(v.drawn.loops, w.loops) &&
               enough(v.drawn.robots, w.robots) && (!w.keyframe || v.drawn.points > 0);
      }, w, { timeout: timeoutMs, polling: 200 });
      return true;
    } catch (e) {
      return false;
    }
  };
  timedOut = !(await reached(want));
  if (!timedOut && rest.includes("--then-stdin")) {
    console.log(JSON.stringify({ live: await page.evaluate(() => window.sglcView) }));
    const next = await lines.next();
    timedOut = !(await reached({ ...want, keyframe: false, ...JSON.parse(next.value) }));
  }
  const result = await page.evaluate(() => {
    const canvas = document.getElementById("view");
    const pixels = canvas.getContext("2d").getImageData(0, 0, canvas.width, canvas.height).data;
    const near = (i, r, g, b) => Math.abs(pixels[i] - r) < 40 && Math.abs(pixels[i + 1] - g) < 40 &&
                                 Math.abs(pixels[i + 2] - b) < 40;
    let trajectory = 0, intra = 0, inter = 0;
    for (let i = 0; i < pixels.length; i += 4) {
      if (near(i, 0x4e, 0xa1, 0xff)) trajectory++;
      else if (near(i, 40, 190, 70)) intra++;
      else if (near(i, 230, 40, 40)) inter++;
    }
    const v = window.sglcView;
    return { connected: v.connected, map: v.map, maps: v.maps, drawn: v.drawn, counts: v.counts,
             graphVersion: v.graphVersion, statuses: v.statuses, mapStats: v.mapStats,
             stats: document.getElementById("stats").innerText,
             pixels: { trajectory, intra, inter } };
  });
  await page.screenshot({ path: screenshot });
  console.log(JSON.stringify({ timeout: timedOut, errors, ...result }));
} finally {
  await browser.close();
}
process.exit(timedOut ? 1 : 0);
