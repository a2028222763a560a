// Runs the Khronos glTF validator (npm: gltf-validator) on .glb files and
// fails on any error or warning. Exit 77 (skipped) when the validator is
// not installed: `npm install -g gltf-validator`.
let validator;
try {
  validator = require('gltf-validator');
} catch (e) {
  try {
    const root = require('child_process').execSync('npm root -g', {stdio: ['ignore', 'pipe', 'ignore']}).toString().trim();
    validator = require(require('path').join(root, 'gltf-validator'));
  } catch (e2) {
    console.log('gltf-validator not installed (npm install -g gltf-validator): skipped');
    process.exit(77);
  }
}
const fs = require('fs');
(async () => {
  let bad = 0;
  for (const file of process.argv.slice(2)) {
    const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(file)));
    const i = report.issues;
    console.log(`${file}: ${i.numErrors} errors, ${i.numWarnings} warnings, ${i.numInfos} infos, ${i.numHints} hints` +
                ` (validator ${report.validatorVersion})`);
    for (const m of i.messages) console.log(`  ${m.severity === 0 ? 'error' : m.severity === 1 ? 'warning' : 'info'}` +
                                            ` ${m.code} ${m.pointer || ''}: ${m.message}`);
    if (i.numErrors || i.numWarnings) bad++;
  }
  process.exit(bad ? 1 : 0);
})().catch((e) => { console.error(e); process.exit(1); });
