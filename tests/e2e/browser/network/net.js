// What the network tests share: a logged-in API per role, a tag's sample,
// operating a device by select-before-operate through the API, and putting
// a device where a test needs it.
import { credentials, Api, requireOk, until } from '../lib.js';

export async function apiAs(role) {
  const c = credentials()[role];
  const api = new Api();
  const r = await api.login(c.user, c.password);
  if (r.status !== 200) throw new Error(`${role} login failed: ${r.status} ${r.text}`);
  return api;
}

export const state = async (api, tag) => (await api.call('GET', `/api/tags/${tag}`)).body;

/** Select and execute through the API; answers the execute's response. */
export async function operateApi(api, device, operation) {
  const sel = await api.call('POST', '/api/switching/selections', { device, operation });
  if (sel.status !== 201) return sel;
  return api.call('POST', `/api/switching/selections/${sel.body.id}/execute`);
}

/** Puts a device where it should be (through the API), waiting for its read-back. */
export async function ensure(api, device, position) {
  const pos = async () => (await state(api, `NET.Sw.${device}.Position`)).value;
  if ((await pos()) !== position) {
    requireOk(await operateApi(api, device, position === 'CLOSED' ? 'close' : 'open'), `${device} to ${position}`);
  }
  await until(`${device} ${position}`, async () => (await pos()) === position);
}
