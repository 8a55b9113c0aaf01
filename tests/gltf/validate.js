// Validates a glTF or GLB file with the Khronos glTF validator (the npm
// package `gltf-validator`, found through NODE_PATH) and prints its report
// as JSON on stdout: `node validate.js FILE`. External resources (buffers,
// images) are read from beside the file. Exit status 0 with a report,
// 2 when the validator cannot run.
const fs = require('fs');
const path = require('path');

let validator;
try {
    validator = require('gltf-validator');
} catch (e) {
    console.error('gltf-validator is not installed (npm install gltf-validator; set NODE_PATH)');
    process.exit(2);
}

const file = process.argv[2];
const bytes = new Uint8Array(fs.readFileSync(file));
const external = (uri) =>
    new Promise((resolve, reject) => {
        const target = path.join(path.dirname(file), decodeURIComponent(uri));
        fs.readFile(target, (err, data) => (err ? reject(err.toString()) : resolve(new Uint8Array(data))));
    });

validator
    .validateBytes(bytes, { uri: path.basename(file), externalResourceFunction: external, maxIssues: 100 })
    .then((report) => {
        console.log(JSON.stringify(report));
    })
    .catch((e) => {
        console.error(String(e));
        process.exit(2);
    });
