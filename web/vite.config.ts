// The page is served by the API under /app/, from services/api/static (see prism_api.webapp).
// Relative asset paths: behind a proxy that adds a prefix the page still finds its files.
import { defineConfig } from "vite";

export default defineConfig({
  base: "./",
  build: {
    outDir: "../services/api/static",
    emptyOutDir: true,
    // three.js alone is ~600 kB minified; one chunk for a single page is fine.
    chunkSizeWarningLimit: 1200,
  },
});
