// Copies the API docs' browser assets (Swagger UI, ReDoc) and their start-up scripts into
// services/api/static/docs, after vite build (which empties static/): /docs and /redoc are then
// served by the API itself, with no CDN, so they work on a network without internet.
import { copyFileSync, mkdirSync, readFileSync, writeFileSync } from "node:fs";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";

const here = dirname(fileURLToPath(import.meta.url));
const out = join(here, "..", "services", "api", "static", "docs");
const files = [
  ["node_modules/swagger-ui-dist/swagger-ui-bundle.js", "swagger-ui-bundle.js"],
  ["node_modules/swagger-ui-dist/swagger-ui.css", "swagger-ui.css"],
  ["node_modules/swagger-ui-dist/favicon-32x32.png", "favicon-32x32.png"],
  ["node_modules/swagger-ui-dist/LICENSE", "swagger-ui.LICENSE.txt"],
  ["node_modules/redoc/bundles/redoc.standalone.js.LICENSE.txt", "redoc.standalone.js.LICENSE.txt"],
  ["docs/swagger-init.js", "swagger-init.js"],
  ["docs/redoc-init.js", "redoc-init.js"],
  ["docs/redoc-logo-mini.svg", "redoc-logo-mini.svg"],
];
mkdirSync(out, { recursive: true });
for (const [from, to] of files) copyFileSync(join(here, from), join(out, to));

// ReDoc shows its maker's logo from a CDN: the one absolute URL it loads, pointed at a local file.
const cdnLogo = "https://cdn.redoc.ly/redoc/logo-mini.svg";
const redoc = readFileSync(join(here, "node_modules/redoc/bundles/redoc.standalone.js"), "utf8");
if (!redoc.includes(cdnLogo)) throw new Error(`redoc.standalone.js no longer names ${cdnLogo}: check what it loads`);
writeFileSync(join(out, "redoc.standalone.js"), redoc.replaceAll(cdnLogo, "static/docs/redoc-logo-mini.svg"));
