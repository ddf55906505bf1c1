// Bundle src/viewer.js with three.js into one minified IIFE for the report pages,
// and copy three.js's licence beside it.
import { build } from 'esbuild';
import { copyFileSync, mkdirSync, statSync } from 'node:fs';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const assets = join(here, '..', 'src', 'lidarfx', 'report', 'assets');
mkdirSync(assets, { recursive: true });
const out = join(assets, 'viewer.min.js');
await build({
  entryPoints: [join(here, 'src', 'viewer.js')],
  bundle: true,
  format: 'iife',
  minify: true,
  target: ['chrome100', 'firefox100', 'safari15'],
  legalComments: 'inline',
  outfile: out,
  logLevel: 'warning',
});
copyFileSync(join(here, 'node_modules', 'three', 'LICENSE'), join(assets, 'THREE_LICENSE.txt'));
console.log(`${out}: ${statSync(out).size} bytes`);
