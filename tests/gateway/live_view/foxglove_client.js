// A viewer built on the Foxglove WebSocket protocol's own client library
// (@foxglove/ws-protocol, from npm): connects, subscribes to every channel it is told of,
// and prints what it receives as JSON lines until SECONDS have passed (or SIGTERM).
//   node foxglove_client.js URL SECONDS [TOKEN]
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");

const [url, seconds, token] = process.argv.slice(2);
const headers = token ? { Authorization: `Bearer ${token}` } : {};
const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL], { headers });
const client = new FoxgloveClient({ ws });
const channels = new Map();
let done = false;
const print = (line) => done || process.stdout.write(JSON.stringify(line) + "\n");
// Exits once everything printed has been written out (a pipe takes it in pieces).
const finish = () => {
  done = true;
  process.stdout.write("", () => process.exit(0));
};

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
client.on("error", (error) => print({ error: String(error) }));
client.on("close", (event) => {
  print({ close: event.code });
  finish();
});
process.on("SIGTERM", finish);
setTimeout(() => {
  client.close();
  finish();
}, Number(seconds) * 1000);
