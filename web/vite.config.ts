// The page is served by the API under /app/, from services/api/static (see prism_api.webapp).
import { defineConfig } from "vite";

export default defineConfig({
  base: "/app/",
  build: {
    outDir: "../services/api/static",
    emptyOutDir: true,
    // three.js alone is ~600 kB minified; one chunk for a single page is fine.
    chunkSizeWarningLimit: 1200,
  },
});
