// A viewer built on the Foxglove WebSocket protocol's own client library
// (@foxglove/ws-protocol, from npm): connects, subscribes to every channel it is told of,
// and prints what it receives as JSON lines until SECONDS have passed (or SIGTERM).
//   node foxglove_client.js URL SECONDS [TOKEN]
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");

const [url, seconds, token] = process.argv.slice(2);
const headers = token ? { Authorization: `Bearer ${token}` } : {};
// With FOXGLOVE_CLIENT_RETRY=1 a refused connection is tried again every 100 ms, so a viewer
// started before its server listens is subscribed the moment the server starts.
const retry = process.env.FOXGLOVE_CLIENT_RETRY === "1";
const channels = new Map();
let done = false;
const print = (line) => done || process.stdout.write(JSON.stringify(line) + "\n");
// Exits once everything printed has been written out (a pipe takes it in pieces).
const finish = () => {
  done = true;
  process.stdout.write("", () => process.exit(0));
};

let current = null;
function connect() {
  const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL], { headers });
  let opened = false;
  ws.on("open", () => { opened = true; });
  const client = new FoxgloveClient({ ws });
  current = client;
  client.on("serverInfo", (info) => print({ serverInfo: info }));
  client.on("advertise", (advertised) => {
    print({ advertise: advertised });
    for (const channel of advertised) {
      channels.set(client.subscribe(channel.id), channel.id);
    }
  });
  client.on("message", ({ subscriptionId, timestamp, data }) => {
    const bytes = Buffer.from(data.buffer, data.byteOffset, data.byteLength);
    print({ message: { channelId: channels.get(subscriptionId), logTime: String(timestamp),
                       data: bytes.toString("base64") } });
  });
  client.on("error", (error) => (retry && !opened) || print({ error: String(error) }));
  client.on("close", (event) => {
    if (retry && !opened && !done) {
      setTimeout(connect, 100);
      return;
    }
    print({ close: event.code });
    finish();
  });
}

connect();
process.on("SIGTERM", finish);
setTimeout(() => {
  current.close();
  finish();
}, Number(seconds) * 1000);
